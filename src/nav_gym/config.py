"""Environment configuration: actions, episode limit, reward weights and how to reach the sim."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from nav_gym.errors import TrainConfigError

SIM_MODES = ('auto', 'attach', 'embedded')


def _f(default: Any, help: str) -> Any:
    return field(default=default, metadata={'help': help})


@dataclass(frozen=True)
class EnvConfig:
    """Settings of the Gymnasium env (the sim's own settings live in nav_sim.config.SimConfig)."""

    namespace: str = _f('', "ROS namespace of the sim node ('' = root, or a unique one when "
                        'the env starts its own)')
    sim: str = _f('auto', "'auto': attach to a sim answering in the namespace, else start one; "
                  "'attach': require a running sim; 'embedded': start one (never a second in "
                  'a namespace: two sims there are refused)')
    probe_timeout: float = _f(1.5, "seconds 'auto' (and 'embedded' in a given namespace) looks "
                              'for a running sim before starting one')
    sim_timeout: float = _f(5.0, 'seconds to wait for the sim before a clear error')
    split: str = _f('train', "scenario bank: 'train' or 'heldout' (reset options may override)")
    max_episode_steps: int = _f(100, 'control periods before an episode is truncated '
                                '(100 x 0.512 s = 51 s)')
    forward_speed: float = _f(0.12, 'action 1 (forward): linear velocity in m/s')
    turn_rate: float = _f(0.75, 'actions 0/2 (left/right): angular velocity in rad/s')
    turn_speed: float = _f(0.03, 'actions 0/2: linear velocity while turning in m/s (0: turn in '
                           'place; > 0: an arc, the inner wheel slower, as the workshop allows)')
    progress_weight: float = _f(2.0, 'reward per metre of progress toward the goal')
    step_penalty: float = _f(-0.01, 'reward added every step')
    goal_reward: float = _f(5.0, 'reward for reaching the goal')
    collision_penalty: float = _f(-1.0, 'reward for a collision')
    sim_params: dict = _f(None, 'parameters for a sim the env starts itself (e.g. {"sim_dt": '
                          '0.016})')

    def __post_init__(self) -> None:
        """Refuse settings the env cannot work with (TrainConfigError)."""
        if self.sim not in SIM_MODES:
            raise TrainConfigError(f'sim must be one of {list(SIM_MODES)}, got {self.sim!r}')
        if int(self.max_episode_steps) < 1:
            raise TrainConfigError('max_episode_steps must be >= 1')
        for name in ('probe_timeout', 'sim_timeout', 'forward_speed', 'turn_rate'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise TrainConfigError(f'{name} must be a finite number > 0, got {value!r}')
        if not (math.isfinite(self.turn_speed) and self.turn_speed >= 0):
            raise TrainConfigError(f'turn_speed must be a finite number >= 0, got '
                                   f'{self.turn_speed!r}')
        if self.sim_params is None:
            object.__setattr__(self, 'sim_params', {})
