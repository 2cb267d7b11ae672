"""The sim node's own settings (NodeConfig), its parameter types and the limits ROS puts on them.

The simulation's settings are :class:`nav_sim.core.config.SimConfig` (no ROS); this module adds
what only the ROS adapter has: the node's mode and frames, the realtime timer's period and the
range of a ROS integer parameter.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from nav_sim import interface
from nav_sim.core.config import POSITIVE, TRAIN, Bounds, SimConfig, check_bounds, convert, setting
from nav_sim.errors import ConfigError


def ros_integer_problem(name: str, value: int) -> str | None:
    """Say why ``value`` cannot be the ROS integer parameter ``name`` (None if it can).

    A ROS 2 integer parameter is a signed 64-bit integer.
    """
    if -2**63 <= value < 2**63:
        return None
    return f'{name} must be in [-2**63, 2**63) (a ROS integer parameter), got {value!r}'


MODES = ('lockstep', 'realtime')


@dataclass(frozen=True)
class NodeConfig:
    """Settings of the ``sim_node`` ROS adapter (the simulation itself is in SimConfig)."""

    mode: str = setting('lockstep', "'lockstep': one cmd_vel = one control period; 'realtime': "
                        'free-running at wall-clock rate with the latest cmd_vel')
    seed: int = setting(0, 'scenario seed used by the next reset (non-negative integer)')
    split: str = setting(TRAIN, "scenario bank used by the next reset: 'train' or 'heldout'")
    reset_on_start: bool = setting(True, 'load the scenario of (seed, split) when the node starts')
    realtime_rate: float = setting(1.0, 'realtime mode: simulated seconds per wall-clock second',
                                   POSITIVE)
    cmd_vel_timeout: float = setting(0.5, 'realtime mode: stop the motors after this long (wall '
                                     'seconds) without a cmd_vel', POSITIVE)
    cmd_vel_stamped: bool = setting(False, 'take cmd_vel as geometry_msgs/TwistStamped (what '
                                    "Jazzy's diff_drive_controller takes) instead of Twist; "
                                    'fixed once the node starts')
    publish_clock: bool = setting(True, 'publish sim time on /clock')
    odom_frame: str = setting(interface.ODOM_FRAME, 'frame of the odometry, the goal pose and '
                              "the live view's 3D scene")
    base_frame: str = setting('base_link', 'frame of the robot body')
    camera_frame: str = setting('camera_optical_frame', 'optical frame of the camera images')
    live_port: int = setting(0, 'serve a Foxglove live view (camera, 3D scene, events, '
                             '/diagnostics) on ws://localhost:PORT; 0 = off', Bounds(0, 65535))

    def __post_init__(self) -> None:
        """Refuse values the node cannot run with (ConfigError)."""
        if self.mode not in MODES:
            raise ConfigError(f'mode must be one of {list(MODES)}, got {self.mode!r}')
        check_bounds(self)  # live_port: 0 (off) or a TCP port
        # seed and split are checked when they are set and again by each reset, which reports
        # a bad value as success=false instead of refusing to start the node.


#: every sim_node parameter and its declared type (the type of its default)
PARAMETER_TYPES: dict[str, type] = {f.name: type(f.default) for c in (SimConfig, NodeConfig)
                                    for f in dataclasses.fields(c)}
_NODE_FIELDS = {f.name for f in dataclasses.fields(NodeConfig)}


def check_sim_params(params: dict) -> None:
    """Check sim_node parameters as the node would at its start (names, types, bounds).

    Raises ConfigError in one line; a command that starts a sim checks its parameters here
    before it starts anything.  ``use_sim_time`` is ROS's own.
    """
    unknown = sorted(set(params) - set(PARAMETER_TYPES) - {'use_sim_time'})
    if unknown:
        raise ConfigError(f'unknown sim_node parameter(s) {unknown}; known: '
                          f'{sorted(PARAMETER_TYPES)}')
    SimConfig.from_params(params)
    NodeConfig(**{key: convert(key, PARAMETER_TYPES[key], value)
                  for key, value in params.items() if key in _NODE_FIELDS})

_MAX_TIMER_NS = 2**63 - 1  # a ROS timer period is a signed 64-bit count of nanoseconds


def realtime_period_ns(ctrl_dt: float, realtime_rate: float) -> int:
    """Return the realtime timer period ``ctrl_dt / realtime_rate`` in ns, or raise ConfigError.

    The period must be a whole number of nanoseconds a ROS timer can hold: from 1 ns to
    2**63 - 1 ns (292 years); the message gives the ``realtime_rate`` range that allows.
    """
    slowest, fastest = ctrl_dt * 1e9 / _MAX_TIMER_NS, ctrl_dt * 1e9
    ok = isinstance(realtime_rate, (int, float)) and not isinstance(realtime_rate, bool) \
        and math.isfinite(realtime_rate) and realtime_rate > 0
    period_ns = ctrl_dt / realtime_rate * 1e9 if ok else math.nan
    if not 1.0 <= period_ns <= _MAX_TIMER_NS:  # False for NaN and inf
        raise ConfigError(
            f'realtime_rate must be in [{_inward(slowest, up=True)}, '
            f'{_inward(fastest, up=False)}] with ctrl_dt '
            f'{ctrl_dt:g} s (the timer period ctrl_dt / realtime_rate must be 1 ns to 292 '
            f'years), got {realtime_rate!r}')
    return int(period_ns)


def _inward(bound: float, up: bool) -> str:
    """Write a range bound with 3 significant digits, rounded into the range."""
    text = f'{bound:.3g}'
    if (float(text) < bound) if up else (float(text) > bound):
        unit = 10.0 ** (math.floor(math.log10(bound)) - 2)
        text = f'{float(text) + (unit if up else -unit):.3g}'
    return text
