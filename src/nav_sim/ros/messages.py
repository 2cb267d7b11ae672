"""Conversions between the simulation core and standard ROS 2 messages (no rclpy node code).

Topics of one control period share one stamp (sim time).  The episode event travels as a
``diagnostic_msgs/DiagnosticArray`` with one status named ``nav_sim/episode`` whose ``message`` is
the event (``reset``, ``none``, ``goal`` or ``collision``) and whose key/values carry the
counters (``period``, ``episode``, ``episode_step``), the scenario (``seed``, ``split``), the
``distance`` to the goal, ``physics_steps`` and ``done``.
"""

from __future__ import annotations

import array
import math
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, Quaternion, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image

from nav_sim.core.events import EVENT_COLLISION
from nav_sim.errors import ScenarioError
from nav_sim.ros.settings import ros_integer_problem

EVENT_STATUS_NAME = 'nav_sim/episode'
EVENT_RESET = 'reset'


def stamp_from_ns(ns: int) -> Time:
    """Convert integer nanoseconds to a ``builtin_interfaces/Time`` stamp."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_to_ns(stamp: Time) -> int:
    """Convert a ``builtin_interfaces/Time`` stamp to integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def yaw_quaternion(yaw: float) -> Quaternion:
    """Return the quaternion of a rotation by ``yaw`` radians about the z axis."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def image_msg(rgb: np.ndarray, stamp: Time, frame_id: str) -> Image:
    """Build an ``rgb8`` Image from an (H, W, 3) uint8 array."""
    height, width, _ = rgb.shape
    msg = Image(height=height, width=width, encoding='rgb8', is_bigendian=0, step=width * 3)
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.data = array.array('B', np.ascontiguousarray(rgb).tobytes())
    return msg


def cmd_vel_class(stamped: bool) -> type:
    """Return the ``cmd_vel`` message class: ``TwistStamped`` if ``stamped``, else ``Twist``."""
    return TwistStamped if stamped else Twist


def cmd_vel_msg(linear: float, angular: float, stamp: Time | None = None,
                frame_id: str = '') -> Twist | TwistStamped:
    """Return a ``cmd_vel``: a ``Twist``, or a ``TwistStamped`` when ``stamp`` is given."""
    twist = Twist()
    twist.linear.x, twist.angular.z = float(linear), float(angular)
    if stamp is None:
        return twist
    msg = TwistStamped(twist=twist)
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    return msg


def twist_of(msg: Twist | TwistStamped) -> Twist:
    """Return the ``Twist`` a ``cmd_vel`` carries (itself, or a ``TwistStamped``'s)."""
    return msg.twist if isinstance(msg, TwistStamped) else msg


def camera_info_msg(width: int, height: int, fovy_deg: float, stamp: Time,
                    frame_id: str) -> CameraInfo:
    """Pinhole intrinsics of the MuJoCo camera (square pixels, no distortion)."""
    fy = (height / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    cx, cy = width / 2.0, height / 2.0
    msg = CameraInfo(width=width, height=height, distortion_model='plumb_bob')
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.d = [0.0] * 5
    msg.k = [fy, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [fy, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return msg


def odometry_msg(pose: tuple[float, float, float], twist: tuple[float, float], stamp: Time,
                 frame_id: str, child_frame_id: str) -> Odometry:
    """Ground-truth pose (odom frame) and body-frame twist."""
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    msg.pose.pose.position.x, msg.pose.pose.position.y = pose[0], pose[1]
    msg.pose.pose.orientation = yaw_quaternion(pose[2])
    msg.twist.twist.linear.x = twist[0]
    msg.twist.twist.angular.z = twist[1]
    return msg


def goal_msg(goal: tuple[float, float], stamp: Time, frame_id: str) -> PoseStamped:
    """Build a PoseStamped at the goal's (x, y) with identity orientation."""
    msg = PoseStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.pose.position.x, msg.pose.position.y = goal
    msg.pose.orientation.w = 1.0
    return msg


def clock_msg(stamp: Time) -> Clock:
    """Build a ``/clock`` message for the given sim time stamp."""
    return Clock(clock=stamp)


def event_msg(event: str, values: dict[str, Any], stamp: Time) -> DiagnosticArray:
    """Build the episode event message of a control period with its counters as key/values."""
    level = DiagnosticStatus.WARN if event == EVENT_COLLISION else DiagnosticStatus.OK
    status = DiagnosticStatus(level=level, name=EVENT_STATUS_NAME, message=event,
                              hardware_id='nav_sim')
    status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = stamp
    return msg


def parse_event(msg: DiagnosticArray) -> dict[str, Any] | None:
    """Return the event dict of an episode event message, or None if it carries none.

    Returns ``event`` plus the key/values with numbers and booleans converted back.
    """
    for status in msg.status:
        if status.name == EVENT_STATUS_NAME:
            out: dict[str, Any] = {'event': status.message}
            for kv in status.values:
                out[kv.key] = _parse_value(kv.value)
            return out
    return None


def _parse_value(text: str) -> Any:
    if text in ('True', 'False'):
        return text == 'True'
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def diagnostics_msg(name: str, message: str, values: dict[str, Any], stamp: Time,
                    hardware_id: str = 'visnav') -> DiagnosticArray:
    """Build a ``/diagnostics`` DiagnosticArray with one OK status (numbers as text, 4 digits)."""
    status = DiagnosticStatus(level=DiagnosticStatus.OK, name=name, message=message,
                              hardware_id=hardware_id)
    status.values = [KeyValue(key=k, value=f'{v:.4g}' if isinstance(v, float) else str(v))
                     for k, v in values.items()]
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = stamp
    return msg


def parameter_msg(name: str, value: Any) -> ParameterMsg:
    """Return a parameter message of a Python value (bool, int, float or else a string).

    An int must fit a ROS integer parameter and a float must be finite (ScenarioError).
    """
    pv = ParameterValue()
    if isinstance(value, bool):
        pv.type, pv.bool_value = ParameterType.PARAMETER_BOOL, value
    elif isinstance(value, (int, np.integer)):
        problem = ros_integer_problem(name, int(value))
        if problem:
            raise ScenarioError(problem)
        pv.type, pv.integer_value = ParameterType.PARAMETER_INTEGER, int(value)
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise ScenarioError(f'{name} must be finite, got {value}')
        pv.type, pv.double_value = ParameterType.PARAMETER_DOUBLE, value
    else:
        pv.type, pv.string_value = ParameterType.PARAMETER_STRING, str(value)
    return ParameterMsg(name=name, value=pv)
