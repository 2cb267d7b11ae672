"""The topics a recording subscribes to: name, type, message class, QoS and whether stamped."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.qos import QoSProfile
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState

from nav_eval.recording.bags import (
    IMAGE_TOPIC,
)
from nav_sim import interface
from nav_sim.ros import qos


@dataclass(frozen=True)
class RecordedTopic:
    """One topic the recorder subscribes to."""

    name: str             # relative to the namespace (absolute for /clock)
    msgtype: str          # ROS 2 type name, as stored in the bag
    msg_class: type       # rclpy message class to subscribe with
    profile: QoSProfile   # what the publisher offers (nav_sim.ros.qos); the recorder queues deeper
    stamped: bool         # starts with a builtin_interfaces/Time (header stamp, Clock value)


TOPICS = (
    RecordedTopic(IMAGE_TOPIC, interface.IMAGE_TYPE, Image, qos.OBSERVATION, True),
    RecordedTopic(interface.CAMERA_INFO_TOPIC, interface.CAMERA_INFO_TYPE, CameraInfo,
                  qos.OBSERVATION, True),
    RecordedTopic(interface.ODOM_TOPIC, interface.ODOM_TYPE, Odometry, qos.OBSERVATION, True),
    RecordedTopic(interface.GOAL_TOPIC, interface.GOAL_TYPE, PoseStamped, qos.LATCHED, True),
    RecordedTopic(interface.EVENT_TOPIC, interface.EVENT_TYPE, DiagnosticArray,
                  qos.OBSERVATION, True),
    RecordedTopic(interface.CMD_VEL_TOPIC, interface.CMD_VEL_TYPE, Twist, qos.CONTROL, False),
    RecordedTopic(interface.CLOCK_TOPIC, interface.CLOCK_TYPE, Clock, qos.CLOCK, True),
)


#: the sim's topics and the policy node's decisions
WITH_POLICY = (*TOPICS, RecordedTopic(interface.DECISION_TOPIC, interface.DECISION_TYPE,
                                      JointState, qos.DECISIONS, True))


def with_cmd_vel(topics: tuple[RecordedTopic, ...], stamped: bool) -> tuple[RecordedTopic, ...]:
    """Return ``topics`` recording ``cmd_vel`` as TwistStamped if ``stamped`` (else as given).

    A subscription hears only publishers of its own type, so the recorder takes the setting
    the sim and its clients share (``cmd_vel_stamped``).  A TwistStamped's stamp is the
    sender's clock, not the sim's, so the bag still places it at the sim time so far.
    """
    if not stamped:
        return topics
    return tuple(dataclasses.replace(t, msgtype=interface.CMD_VEL_STAMPED_TYPE,
                                     msg_class=TwistStamped)
                 if t.name == interface.CMD_VEL_TOPIC else t for t in topics)


def bag_qos(profile: QoSProfile) -> Qos:
    """Return the rosbags form of an rclpy QoS profile (durations left at the default)."""
    default = QosTime(0, 0)
    return Qos(QosHistory(profile.history.value), profile.depth,
               QosReliability(profile.reliability.value), QosDurability(profile.durability.value),
               default, default, QosLiveliness(profile.liveliness.value), default, False)
