"""The simulation's settings (SimConfig), the one conversion of every setting, and scenario splits.

Every field carries a one-line description in its metadata; the ROS node declares one parameter per
field with that description, and ``config/sim.yaml`` holds the defaults a user may change.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import Any

from nav_sim.core.world_file import ENV_SETTINGS, SETTING_PREFIX, world_settings
from nav_sim.errors import ConfigError, ScenarioError, WorldError
from nav_sim.paths import find_world

#: the scenario banks' names: training scenarios and the held-out ones (docs/worlds.md)
TRAIN, HELDOUT = 'train', 'heldout'
SPLITS = (TRAIN, HELDOUT)
#: every spelling a user may give (``normalise_split``) -> the bank's name
SPLIT_ALIASES = {TRAIN: TRAIN, 'training': TRAIN, HELDOUT: HELDOUT, 'held-out': HELDOUT,
                 'held_out': HELDOUT, 'test': HELDOUT}


_TYPE_WORDS = {bool: 'true or false', int: 'an integer', float: 'a number', str: 'a string'}


def convert(name: str, kind: type, value: Any) -> Any:
    """Return ``value`` as the declared type ``kind`` of setting ``name``, or raise ConfigError.

    The one conversion of every setting, whether it comes from a ROS parameter, a YAML file or
    the command line (where every value is a string).  It never loses information:
    ``bool`` takes ``True``/``False`` or the strings ``true``/``false`` (any case); ``int``
    takes an integer, or a float or string with an integral value (``4``, ``4.0``, ``'4.0'``),
    never ``3.7``; ``float`` takes an int, a float or a numeric string; ``str`` takes a string.
    A bool is never taken as a number.
    """
    word = _TYPE_WORDS.get(kind, kind.__name__)
    error = ConfigError(f'{name} takes {word}, got {value!r}')
    if kind is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.strip().lower() in ('true', 'false'):
            return value.strip().lower() == 'true'
        raise error
    if kind is str:
        if isinstance(value, str):
            return value
        raise error
    if kind not in (int, float):
        if isinstance(value, kind):
            return value
        raise error
    if isinstance(value, bool):
        raise error
    if isinstance(value, str):
        try:
            number: Any = int(value.strip()) if kind is int else float(value)
        except ValueError:
            try:
                number = float(value)
            except ValueError:
                raise error from None
    elif isinstance(value, numbers.Real):
        number = value
    else:
        raise error
    if kind is float:
        try:
            return float(number)
        except OverflowError:  # an int beyond the float range
            raise error from None
    if isinstance(number, numbers.Integral):
        return int(number)
    if math.isfinite(number) and float(number).is_integer():
        return int(number)
    raise error


@dataclass(frozen=True)
class Bounds:
    """The values a numeric setting allows: finite, from ``low`` to ``high``.

    Each bound is included unless its ``*_open`` flag says otherwise.  The one place where a
    setting's range is stated: :func:`check_bounds` enforces it wherever a config is built (the
    CLI, a params or YAML file, a sweep's ``--set``, a ROS parameter), and the tests generate
    their cases from it (:meth:`outside`).
    """

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False

    def allows(self, value: Any) -> bool:
        """Tell whether ``value`` is a finite real number within the bounds."""
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return False
        if not math.isfinite(value):
            return False
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def describe(self) -> str:
        """Say what is allowed: '> 0', '>= 1', 'in (0, 1]', 'a finite number'."""
        low, high = _number(self.low), _number(self.high)
        if math.isinf(self.low) and math.isinf(self.high):
            return 'a finite number'
        if math.isinf(self.high):
            return f"{'>' if self.low_open else '>='} {low}"
        if math.isinf(self.low):
            return f"{'<' if self.high_open else '<='} {high}"
        return (f"in {'(' if self.low_open else '['}{low}, {high}"
                f"{')' if self.high_open else ']'}")

    def outside(self, kind: type) -> list[Any]:
        """Return values of type ``kind`` just outside the bounds (and NaN, inf for floats)."""
        step = 1 if kind is int else 1e-3
        values: list[Any] = [] if kind is int else [math.nan, math.inf]
        if not math.isinf(self.low):
            values.append(kind(self.low) if self.low_open else kind(self.low - step))
        if not math.isinf(self.high):
            values.append(kind(self.high) if self.high_open else kind(self.high + step))
        return values


POSITIVE = Bounds(0.0, low_open=True)
NON_NEGATIVE = Bounds(0.0)
AT_LEAST_ONE = Bounds(1.0)
FRACTION = Bounds(0.0, 1.0)
FINITE = Bounds()


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else f'{value:g}'


def setting(default: Any, help: str, bounds: Bounds | None = None) -> Any:
    """Declare a config dataclass field with its default, its one-line description and range.

    The description is what the ROS parameter descriptor, the params file and ``--help`` say;
    ``bounds`` (a number's allowed values) is checked by :func:`check_bounds`.
    """
    metadata: dict[str, Any] = {'help': help}
    if bounds is not None:
        metadata['bounds'] = bounds
    return field(default=default, metadata=metadata)


def check_bounds(config: Any, error: type[Exception] = ConfigError) -> None:
    """Raise ``error`` for the first field of ``config`` outside its bounds: name, value, range."""
    for item in dataclasses.fields(config):
        bounds = item.metadata.get('bounds')
        value = getattr(config, item.name)
        if bounds is not None and not bounds.allows(value):
            raise error(f'{item.name} must be {bounds.describe()}, got {value!r}')


@dataclass(frozen=True)
class SimConfig:
    """Parameters of the world, the robot, the camera and the task (no ROS)."""

    world: str = setting('arena.xml', 'MJCF world: a name under share/nav_sim/worlds (arena.xml, '
                         'clutter.xml, rooms.xml) or a path (docs/worlds.md)')
    sim_dt: float = setting(0.032, 'physics timestep in seconds (Webots basicTimeStep default: '
                            '32 ms)', POSITIVE)
    action_repeat: int = setting(16, 'physics steps per control period (ctrl_dt = sim_dt * '
                                 'repeat)', AT_LEAST_ONE)
    settle_steps: int = setting(2, 'physics steps with motors stopped after a reset', AT_LEAST_ONE)
    wheel_radius: float = setting(0.0205, 'wheel radius in metres (e-puck: 2.05 cm)', POSITIVE)
    axle_length: float = setting(0.052, 'distance between the wheels in metres (e-puck: 5.2 cm)',
                                 POSITIVE)
    max_wheel_speed: float = setting(6.28, 'wheel speed limit in rad/s (e-puck: 6.28 rad/s)',
                                     POSITIVE)
    camera_width: int = setting(128, 'native camera image width in pixels', AT_LEAST_ONE)
    camera_height: int = setting(96, 'native camera image height in pixels', AT_LEAST_ONE)
    camera_hfov_deg: float = setting(90.0, 'horizontal field of view in degrees (e-puck: 0.84 '
                                     'rad = 48°; a wide-angle lens by default)',
                                     Bounds(1.0, 170.0))
    camera_near_clip: float = setting(0.005, 'camera near clipping distance in metres (surfaces '
                                      'closer than this are not drawn)', POSITIVE)
    camera_mount_forward: float = setting(0.0, 'camera position ahead of the robot centre in '
                                          "metres (0: on a mast over the centre; the e-puck's "
                                          'own camera is at the front edge, 0.038)', FINITE)
    camera_mount_height: float = setting(0.10, 'camera height above the floor in metres (e-puck: '
                                         '0.0455)', POSITIVE)
    camera_pitch_deg: float = setting(25.0, 'camera tilt below the horizontal in degrees '
                                      '(e-puck: 0, level)', Bounds(-89.0, 89.0))
    goal_radius: float = setting(0.1, 'success when the robot centre is this close to the goal '
                                 '(m)', POSITIVE)
    goal_marker_radius: float = setting(0.05, 'radius of the green goal cylinder in metres',
                                        POSITIVE)
    goal_marker_height: float = setting(0.3, 'height of the green goal cylinder in metres (a '
                                        'beacon taller than the 16 cm obstacles)', POSITIVE)
    min_start_goal_distance: float = setting(0.6, 'minimum straight-line start-goal distance (m)',
                                             POSITIVE)
    num_obstacles: int = setting(3, 'obstacles per layout (at most the slots in the world)',
                                 NON_NEGATIVE)
    obstacle_gap: float = setting(0.15, 'free gap in metres between the placed obstacles and to '
                                  'the walls (0.15: wider than the 7.4 cm robot)', POSITIVE)
    train_layouts: int = setting(20, 'number of layouts in the training bank', AT_LEAST_ONE)
    heldout_layouts: int = setting(10, 'number of layouts in the held-out bank', AT_LEAST_ONE)
    train_bank_seed: int = setting(1_000, 'seed that generates the training layout bank',
                                   NON_NEGATIVE)
    heldout_bank_seed: int = setting(2_000, 'seed that generates the held-out layout bank',
                                     NON_NEGATIVE)
    randomize_look: bool = setting(False, 'draw the colours of floor, walls and obstacles and '
                                   "the light from each scenario's seed (training and held-out "
                                   'palettes are disjoint; the goal keeps its green)')

    @property
    def ctrl_dt(self) -> float:
        """Duration of one control period in seconds."""
        return self.sim_dt * self.action_repeat

    @property
    def camera_fovy_deg(self) -> float:
        """Vertical field of view that gives ``camera_hfov_deg`` at the camera aspect ratio."""
        half = math.radians(self.camera_hfov_deg) / 2.0
        return math.degrees(2.0 * math.atan(math.tan(half) * self.camera_height
                                            / self.camera_width))

    def __post_init__(self) -> None:
        """Refuse values the simulation cannot run with (ConfigError): each field's bounds."""
        # settle_steps >= 1: the reset frame must get a new stamp (clients tell it from the
        # previous episode's last frame by the stamp)
        check_bounds(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> SimConfig:
        """Build from a mapping, rejecting unknown keys with the list of known ones.

        A parameter the mapping leaves out takes its world's setting, if the world has one
        (:meth:`world_defaults`), else its default.
        """
        known = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ConfigError(f'unknown simulation parameter(s) {unknown}; known: {sorted(known)}')
        given = {key: convert(key, type(known[key].default), value)
                 for key, value in values.items()}
        return cls(**{**cls.world_defaults(given.get('world', cls.world)), **given})

    @classmethod
    def world_defaults(cls, world: str) -> dict[str, Any]:
        """Return the sim parameters a world sets (its ``visnav:`` settings), typed.

        Raises WorldNotFoundError, or WorldError for a setting that is neither a sim parameter
        nor one of ``nav_sim.core.world_file.ENV_SETTINGS`` or that has the wrong type.
        """
        known = {f.name: f for f in dataclasses.fields(cls) if f.name != 'world'}
        out = {}
        for name, value in world_settings(world).items():
            if name in ENV_SETTINGS:
                continue
            if name not in known:
                raise WorldError(f'{find_world(world)}: unknown setting "{SETTING_PREFIX}{name}"; '
                                 f'a world sets sim parameters {sorted(known)} or '
                                 f'{list(ENV_SETTINGS)}')
            try:
                out[name] = convert(name, type(known[name].default), value)
            except ConfigError as exc:
                raise WorldError(f'{find_world(world)}: setting {SETTING_PREFIX}{exc}') from None
        return out

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> SimConfig:
        """Build from the simulation part of a sim_node parameter mapping.

        Node parameters such as ``publish_clock`` are left out; bad simulation values raise
        ConfigError.
        """
        names = {f.name for f in dataclasses.fields(cls)}
        return cls.from_dict({k: v for k, v in params.items() if k in names})


def normalise_split(split: str) -> str:
    """Return the canonical split name ('train' or 'heldout') or raise ScenarioError."""
    key = str(split).strip().lower()
    if key not in SPLIT_ALIASES:
        raise ScenarioError(f'unknown split {split!r}: use one of {list(SPLITS)}')
    return SPLIT_ALIASES[key]


def validate_seed(seed: Any) -> int:
    """Return the seed as a non-negative int or raise ScenarioError."""
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ScenarioError(f'seed must be a non-negative integer, got {seed!r}')
    if int(seed) < 0 or int(seed) >= 2**63:
        raise ScenarioError(f'seed must be in [0, 2**63), got {seed!r}')
    return int(seed)
