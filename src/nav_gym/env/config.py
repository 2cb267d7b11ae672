"""Environment configuration: actions, episode limit, reward weights and how to reach the sim."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import yaml

from nav_gym.errors import TrainConfigError
from nav_sim.core.config import (
    FINITE,
    NON_NEGATIVE,
    POSITIVE,
    SimConfig,
    check_bounds,
    convert,
    setting,
)
from nav_sim.core.world_file import SETTING_PREFIX, world_settings
from nav_sim.errors import ConfigError, WorldError
from nav_sim.interface import absolute_namespace
from nav_sim.paths import find_world
from nav_sim.ros.settings import check_sim_params

SIM_MODES = ('auto', 'attach', 'embedded')
#: the episode limit of a world that sets none (arena.xml): 100 decisions x 0.512 s = 51 s
DEFAULT_EPISODE_STEPS = 100


def parse_mapping(value: Any, what: str) -> dict[str, Any]:
    """Return ``value`` as a mapping: a dict as it is, a string parsed as YAML (JSON is YAML).

    The one reading of ``sim_params``, whether from a YAML file, ``--sim-params`` or a sweep's
    ``--set``; anything else raises TrainConfigError naming ``what``.
    """
    try:
        parsed = yaml.safe_load(value) if isinstance(value, str) else value
    except yaml.YAMLError:
        parsed = None
    if not isinstance(parsed, dict):
        raise TrainConfigError(f"{what} takes a mapping, e.g. '{{world: rooms.xml}}', got "
                               f'{value!r}')
    return parsed


def world_episode_steps(sim_params: dict[str, Any]) -> int:
    """Return the episode limit of the world in ``sim_params`` (its ``max_episode_steps``).

    ``DEFAULT_EPISODE_STEPS`` for a world that sets none; raises WorldNotFoundError, or
    WorldError for a setting that is not a whole number >= 1.
    """
    world = str(sim_params.get('world', SimConfig.world))
    value = world_settings(world).get('max_episode_steps')
    if value is None:
        return DEFAULT_EPISODE_STEPS
    try:
        steps = convert('max_episode_steps', int, value)
    except ConfigError as exc:
        raise WorldError(f'{find_world(world)}: setting {SETTING_PREFIX}{exc}') from None
    if steps < 1:
        raise WorldError(f'{find_world(world)}: setting {SETTING_PREFIX}max_episode_steps must '
                         f'be >= 1, got {steps}')
    return steps


@dataclass(frozen=True)
class EnvConfig:
    """Settings of the Gymnasium env (the sim's own: nav_sim.core.config.SimConfig).

    The one definition of the env's settings: TrainConfig declares the same fields from these
    (default and description), and the episode limit ``0`` is resolved to the world's here.
    """

    namespace: str = setting('', "ROS namespace of the sim node ('' = root, or a unique one when "
                             'the env starts its own)')
    sim: str = setting('auto', "'auto': attach to a sim answering in the namespace, else start "
                       "one; 'attach': require a running sim; 'embedded': start one (never a "
                       'second in a namespace: two sims there are refused)')
    probe_timeout: float = setting(1.5, "seconds 'auto' (and 'embedded' in a given namespace) "
                                   'looks for a running sim before starting one', POSITIVE)
    sim_timeout: float = setting(5.0, 'seconds to wait for the sim before a clear error', POSITIVE)
    cmd_vel_stamped: bool = setting(False, 'send cmd_vel as geometry_msgs/TwistStamped instead '
                                    "of Twist (a sim the env starts gets the same setting; an "
                                    "attached sim's must agree)")
    split: str = setting('train', "scenario bank: 'train' or 'heldout' (reset options may "
                         'override)')
    max_episode_steps: int = setting(0, "control periods before an episode is truncated; 0: the "
                                     "world's limit (arena.xml: 100 x 0.512 s = 51 s; "
                                     'docs/worlds.md)', NON_NEGATIVE)
    forward_speed: float = setting(0.12, 'action 1 (forward): linear velocity in m/s', POSITIVE)
    turn_rate: float = setting(0.75, 'actions 0/2 (left/right): angular velocity in rad/s',
                               POSITIVE)
    turn_speed: float = setting(0.03, 'actions 0/2: linear velocity while turning in m/s (0: '
                                'turn in place; > 0: an arc, the inner wheel slower, as the '
                                'workshop allows)', NON_NEGATIVE)
    progress_weight: float = setting(2.0, 'reward per metre of progress toward the goal', FINITE)
    step_penalty: float = setting(-0.01, 'reward added every step', FINITE)
    goal_reward: float = setting(5.0, 'reward for reaching the goal', FINITE)
    collision_penalty: float = setting(-1.0, 'reward for a collision', FINITE)
    sim_params: dict = setting(None, 'parameters for a sim the env starts itself (e.g. '
                               '{"sim_dt": 0.016})')

    def __post_init__(self) -> None:
        """Refuse settings the env cannot work with (TrainConfigError): each field's bounds."""
        check_bounds(self, TrainConfigError)
        try:  # '/a/b' from here on: the graph's names and the sim's remap agree
            object.__setattr__(self, 'namespace', absolute_namespace(self.namespace))
        except ValueError as exc:
            raise TrainConfigError(f'namespace: {exc}') from None
        if self.sim not in SIM_MODES:
            raise TrainConfigError(f'sim must be one of {list(SIM_MODES)}, got {self.sim!r}')
        if self.sim_params is None:
            object.__setattr__(self, 'sim_params', {})
        if not isinstance(self.sim_params, dict):
            raise TrainConfigError(f'sim_params must be a mapping, got {self.sim_params!r}')
        try:  # what a sim the env starts would refuse, refused before anything starts
            check_sim_params(self.sim_params)
        except ConfigError as exc:
            raise TrainConfigError(f'sim_params: {exc}') from None
        if self.sim_params.get('cmd_vel_stamped', self.cmd_vel_stamped) != self.cmd_vel_stamped:
            raise TrainConfigError(
                f"sim_params sets cmd_vel_stamped {self.sim_params['cmd_vel_stamped']!r} but "
                f'cmd_vel_stamped is {self.cmd_vel_stamped!r}: set cmd_vel_stamped alone (the '
                'env gives a sim it starts the same setting)')
        if self.max_episode_steps == 0:  # the world's limit
            object.__setattr__(self, 'max_episode_steps', world_episode_steps(self.sim_params))
        if int(self.max_episode_steps) < 1:
            raise TrainConfigError("max_episode_steps must be >= 1 (0: the world's limit)")
