"""How the robot moves: differential-drive kinematics and the exact arc of a twist (no MuJoCo).

The one definition shared by the sim's physics steps (:mod:`nav_sim.core.sim`) and the offline
planner (:mod:`nav_sim.core.planner`), which therefore plans without loading MuJoCo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nav_sim.core.config import SimConfig


@dataclass(frozen=True)
class WheelCommand:
    """Wheel angular speeds in rad/s (positive drives forward) after saturation."""

    left: float
    right: float
    saturated: bool = False


def twist_to_wheels(linear: float, angular: float, config: SimConfig) -> WheelCommand:
    """Differential-drive inverse kinematics, saturating at the wheel limit.

    Both wheels are scaled by the same factor so the commanded curvature is kept.  Any finite
    command gives finite wheel speeds within the limit: a command so large that the wheel speeds
    overflow a float (``linear`` near 1e308) is scaled down before it is converted.  Non-finite
    inputs raise ValueError (callers decide whether to reject or stop).
    """
    if not (math.isfinite(linear) and math.isfinite(angular)):
        raise ValueError(f'non-finite velocity command (linear={linear}, angular={angular})')
    left, right = _wheel_speeds(linear, angular, config)
    if not (math.isfinite(left) and math.isfinite(right)):
        # overflow: the same direction from a command scaled into range (it saturates anyway)
        size = max(abs(linear), abs(angular))
        left, right = _wheel_speeds(linear / size, angular / size, config)
        return _saturate(left, right, config.max_wheel_speed, force=True)
    return _saturate(left, right, config.max_wheel_speed, force=False)


def _wheel_speeds(linear: float, angular: float, config: SimConfig) -> tuple[float, float]:
    half_axle = config.axle_length / 2.0
    return ((linear - angular * half_axle) / config.wheel_radius,
            (linear + angular * half_axle) / config.wheel_radius)


def _saturate(left: float, right: float, limit: float, force: bool) -> WheelCommand:
    """Scale both wheels so the faster one runs at ``limit`` if it exceeds it (or ``force``)."""
    peak = max(abs(left), abs(right))
    if peak <= limit and not force:
        return WheelCommand(left, right, False)
    scale = limit / peak
    # rounding can put the product one ulp above the limit
    return WheelCommand(min(max(left * scale, -limit), limit),
                        min(max(right * scale, -limit), limit), True)


def wheels_to_twist(left: float, right: float, config: SimConfig) -> tuple[float, float]:
    """Differential-drive forward kinematics: (linear m/s, angular rad/s)."""
    linear = config.wheel_radius * (left + right) / 2.0
    angular = config.wheel_radius * (right - left) / config.axle_length
    return linear, angular


def arc_step(x: float, y: float, yaw: float, linear: float, angular: float, radius: float,
             straight: bool, dt: float) -> tuple[float, float, float]:
    """Return the pose after ``dt`` on the exact differential-drive arc of a body twist.

    ``radius`` is ``linear / angular`` (unused when ``straight``, i.e. ``|angular| < 1e-9``).
    The one definition of how the robot moves: the sim's physics steps and the planner's.
    """
    if straight:
        return x + linear * dt * math.cos(yaw), y + linear * dt * math.sin(yaw), yaw + angular * dt
    return (x + radius * (math.sin(yaw + angular * dt) - math.sin(yaw)),
            y - radius * (math.cos(yaw + angular * dt) - math.cos(yaw)), yaw + angular * dt)
