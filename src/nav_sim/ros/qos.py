"""QoS profiles of the visnav graph, named once."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: lockstep commands: every message matters, only the newest is useful
CONTROL = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
#: per-period observations (image, camera_info, odom, episode events)
OBSERVATION = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
#: the goal of the current episode, delivered to late joiners
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: a subscription to a latched topic with many publishers (the sim's claims): one each
LATCHED_MANY = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /clock, as the sim publishes it
CLOCK = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                   reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.VOLATILE)
#: camera images for a consumer that must not slow the camera down (the policy node): best
#: effort, only the newest matters (ROS's sensor-data profile with depth 1); it matches the
#: sim's reliable publisher as well as a real camera driver's best-effort one
SENSOR_DATA = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE)
#: the policy node's decisions (for plots, bags and the closed-loop evaluation)
DECISIONS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)

#: the sim's services (reset, stop): a burst of requests is queued, never dropped (ROS's default
#: keeps 10); a request ROS drops before it reaches the sim (a client gone) is not answered
SERVICE_REQUESTS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                              reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
