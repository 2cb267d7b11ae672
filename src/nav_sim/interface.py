"""The graph's ROS 2 interface: the sim node's topic and service names, and the policy node's.

Names are relative, so they resolve in the node's namespace (``ros2 run nav_sim sim_node
--ros-args -r __ns:=/robot1`` publishes ``/robot1/camera/image_raw``).  One definition shared by
the node, its client, the graph checks, the bag recorder and the bag reader.
"""

from __future__ import annotations

import re

NODE_NAME = 'sim_node'
#: the frame of odometry, the goal pose and the live view's 3D scene (sim_node's odom_frame)
ODOM_FRAME = 'odom'

IMAGE_TOPIC = 'camera/image_raw'  # sensor_msgs/Image, rgb8, one per control period
CAMERA_INFO_TOPIC = 'camera/camera_info'  # sensor_msgs/CameraInfo, same stamp
ODOM_TOPIC = 'odom'  # nav_msgs/Odometry, same stamp (privileged: evaluation only)
EVENT_TOPIC = 'episode_event'  # diagnostic_msgs/DiagnosticArray (see nav_sim.ros.messages)
GOAL_TOPIC = 'goal_pose'  # geometry_msgs/PoseStamped, latched, at each reset
CMD_VEL_TOPIC = 'cmd_vel'  # geometry_msgs/Twist (or TwistStamped): one period per message
CLOCK_TOPIC = '/clock'  # rosgraph_msgs/Clock, with publish_clock (global: ROS's sim time)

#: std_msgs/String, latched: a controlling client's claim, JSON {node, host, pid, since_ns}
CLAIM_TOPIC = 'sim_claim'
#: std_msgs/String, latched, from the sim: the claim that holds it and every claim it has heard
#: (JSON {node, host, pid, since_ns, heard: [[node, host, pid, since_ns], ...]}; {"heard": []}
#: while none holds it; see nav_sim.ros.claim)
CONTROLLER_TOPIC = 'sim_controller'

RESET_SERVICE = 'reset'  # std_srvs/Trigger: a new episode (seed and split from parameters)
STOP_SERVICE = 'stop'  # std_srvs/Trigger: stop the robot
PARAMETERS_SERVICE = f'{NODE_NAME}/set_parameters'  # rcl_interfaces/SetParameters

# The policy node (nav_gym.policy_node) subscribes IMAGE_TOPIC and publishes CMD_VEL_TOPIC and
# these; named here, with the sim's, because the live view's layout and the bags show them too.
POLICY_NODE_NAME = 'policy_node'
DECISION_TOPIC = 'policy/decision'  # sensor_msgs/JointState: DECISION_FIELDS as names
POLICY_OBSERVATION_TOPIC = 'policy/observation'  # sensor_msgs/Image, the 84x84 observation
#: std_srvs/Trigger: a new episode starts (the policy's memory begins again), for a robot whose
#: graph has no episode events
POLICY_BEGIN_EPISODE_SERVICE = 'policy/begin_episode'
#: what each decision carries, in this order (the JointState's names and positions): the
#: action (-1: stop), its cmd_vel, the Q-values (NaN without), the image's age at the decision
#: (wall clock since it arrived; node clock since its stamp) and the time to turn it into an
#: action (observation + network; 0 for a repeated decision)
DECISION_FIELDS = ('action', 'linear', 'angular', 'q_left', 'q_forward', 'q_right',
                   'image_age_ms', 'stamp_age_ms', 'inference_ms')

# The ROS 2 type of each topic above, as bags, the live view and the graph checks name it.
IMAGE_TYPE = 'sensor_msgs/msg/Image'                  # IMAGE_TOPIC, POLICY_OBSERVATION_TOPIC
CAMERA_INFO_TYPE = 'sensor_msgs/msg/CameraInfo'       # CAMERA_INFO_TOPIC
ODOM_TYPE = 'nav_msgs/msg/Odometry'                   # ODOM_TOPIC
EVENT_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'    # EVENT_TOPIC (and /diagnostics)
GOAL_TYPE = 'geometry_msgs/msg/PoseStamped'           # GOAL_TOPIC
CMD_VEL_TYPE = 'geometry_msgs/msg/Twist'              # CMD_VEL_TOPIC (the default)
CMD_VEL_STAMPED_TYPE = 'geometry_msgs/msg/TwistStamped'  # CMD_VEL_TOPIC with cmd_vel_stamped
CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'                # CLOCK_TOPIC
DECISION_TYPE = 'sensor_msgs/msg/JointState'          # DECISION_TOPIC: named numbers, stamped
CLAIM_TYPE = 'std_msgs/msg/String'                    # CLAIM_TOPIC, CONTROLLER_TOPIC


def cmd_vel_type(stamped: bool) -> str:
    """Return the type of ``cmd_vel`` with the ``cmd_vel_stamped`` setting ``stamped``.

    ``Twist`` is the workshop's (the default); ``TwistStamped`` is what ROS 2 Jazzy's
    ``diff_drive_controller`` takes.  The sim, its clients and the policy node share the setting.
    """
    return CMD_VEL_STAMPED_TYPE if stamped else CMD_VEL_TYPE

_TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')


def absolute_namespace(namespace: str) -> str:
    """Return a namespace as the graph names it: ``'/a/b'``, or ``'/'`` and ``''`` as given.

    ``'/'`` names the root and ``''`` leaves it unsaid (an env then picks a fresh namespace for
    a sim it starts).  A relative one (``'robot1'``) is taken from the root, as a node given it
    takes it; a namespace ROS would refuse (a token that is empty, starts with a digit or holds
    other characters than letters, digits and ``_``) raises ValueError with one line, before a
    node's ``-r __ns:=`` remap would fail inside rcl.
    """
    if namespace in ('', '/'):
        return namespace
    tokens = namespace.strip('/').split('/')
    if '//' in namespace or not all(_TOKEN.fullmatch(token) for token in tokens):
        raise ValueError(f'{namespace!r} is not a ROS namespace: tokens of letters, digits and '
                         f"'_' that do not start with a digit, separated by '/' (e.g. /robot1)")
    return ''.join(f'/{token}' for token in tokens)


def full_name(namespace: str, name: str) -> str:
    """Return ``name`` joined under ``namespace`` by :func:`absolute_namespace`'s rule.

    ``('/robot1', 'sim')`` and ``('robot1', 'sim')`` give ``'/robot1/sim'``; ``('/', 'sim')``
    and ``('', 'sim')`` give ``'/sim'``: a node's fully qualified name from the graph's
    namespace and name, or a namespace under another (``env0`` under ``/lab``).
    """
    return f"{absolute_namespace(namespace).rstrip('/')}/{name}"
