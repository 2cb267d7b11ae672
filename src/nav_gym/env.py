"""The Gymnasium environment: a ROS 2 client of the ``nav_sim`` node.

Observation: the camera image only, ``Box(0, 255, (3, 84, 84), uint8)``.  Actions:
``Discrete(3)`` = 0 turn left, 1 forward, 2 turn right, sent as ``cmd_vel`` Twists.  Pose, goal,
distance and the scenario go to ``info`` and the reward, never to the policy.
"""

from __future__ import annotations

import itertools
import math
import os
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from nav_gym.config import EnvConfig
from nav_gym.errors import InvalidActionError, ResetNeededError
from nav_gym.observation import OBS_SHAPE, image_msg_to_observation
from nav_sim.client import Frame, SimClient
from nav_sim.config import normalise_split
from nav_sim.errors import FrameSyncError, SimUnavailableError
from nav_sim.sim_process import SimProcess

ACTION_NAMES = ('left', 'forward', 'right')
_instances = itertools.count()


def reward_terms(previous_distance: float, distance: float, event: str,
                 config: EnvConfig) -> dict[str, float]:
    """The workshop reward, term by term: progress, step cost, goal bonus, collision penalty."""
    progress = previous_distance - distance
    return {
        'progress': config.progress_weight * progress,
        'step': config.step_penalty,
        'goal': config.goal_reward if event == 'goal' else 0.0,
        'collision': config.collision_penalty if event == 'collision' else 0.0,
    }


class NavigationEnv(gym.Env):
    """Visual navigation through the nav_sim node, one control period per step (lockstep)."""

    metadata = {'render_modes': ['rgb_array'], 'render_fps': 5}

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        super().__init__()
        base = config or EnvConfig()
        self.config = EnvConfig(**{**base.__dict__, **overrides}) if overrides else base
        if render_mode not in (None, 'rgb_array'):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self.observation_space = spaces.Box(0, 255, OBS_SHAPE, np.uint8)
        self.action_space = spaces.Discrete(len(ACTION_NAMES))
        cfg = self.config
        self._actions = {0: (cfg.turn_speed, cfg.turn_rate), 1: (cfg.forward_speed, 0.0),
                         2: (cfg.turn_speed, -cfg.turn_rate)}
        self._sim_process: SimProcess | None = None
        self._client: SimClient | None = None
        self._frame: Frame | None = None
        self._rgb: np.ndarray | None = None
        self._episode_over = True
        self.step_count = 0
        self.previous_distance = math.nan
        self._connect()

    # --- connection -----------------------------------------------------------------------
    def _connect(self) -> None:
        cfg = self.config
        namespace = cfg.namespace
        if cfg.sim == 'embedded' and not namespace:
            namespace = f'/visnav_env_{os.getpid()}_{next(_instances)}'
        client = SimClient(namespace, timeout=cfg.sim_timeout,
                           node_name=f'visnav_env_{os.getpid()}_{next(_instances)}')
        try:
            if cfg.sim == 'attach':
                client.wait_for_sim(cfg.sim_timeout)
            elif cfg.sim == 'auto' and _sim_answers(client, cfg.probe_timeout):
                pass
            else:
                if cfg.sim == 'auto' and not namespace:
                    client.close()
                    namespace = f'/visnav_env_{os.getpid()}_{next(_instances)}'
                    client = SimClient(namespace, timeout=cfg.sim_timeout,
                                       node_name=f'visnav_env_{os.getpid()}')
                params = {'publish_clock': False, **cfg.sim_params}
                self._sim_process = SimProcess(namespace=namespace, params=params)
                client.wait_for_sim(max(cfg.sim_timeout, 30.0), self._sim_process.failure)
        except BaseException:
            client.close()
            self._stop_sim()
            raise
        self._client = client

    @property
    def client(self) -> SimClient:
        if self._client is None:
            raise SimUnavailableError('the environment is closed')
        return self._client

    @property
    def namespace(self) -> str:
        return self.client.namespace

    @property
    def last_stamp_ns(self) -> int:
        """Sim-time stamp of the latest observation (-1 before the first reset)."""
        return -1 if self._frame is None else self._frame.stamp_ns

    # --- Gymnasium API --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.stop_motors()
        options = options or {}
        split = normalise_split(options.get('split', self.config.split))
        scenario_seed = options.get('scenario_seed', seed)
        if scenario_seed is None:
            scenario_seed = int(self.np_random.integers(0, 2**31 - 1))
        frame, scenario = self.client.reset(int(scenario_seed), split)
        self._accept(frame)
        self.step_count = 0
        self.previous_distance = float(frame.event['distance'])
        self._episode_over = False
        obs = self._observation
        info = {'scenario': scenario, 'seed': int(scenario_seed), 'split': split,
                'distance': self.previous_distance, 'pose': frame.pose,
                'goal': tuple(scenario['goal']), 'episode': frame.event['episode']}
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        index = self._validate_action(action)
        if self._episode_over or self._frame is None:
            raise ResetNeededError('the episode is over (or never started): call reset() first')
        linear, angular = self._actions[index]
        frame = self.client.step(linear, angular, self._frame)
        if frame.event['episode'] != self._frame.event['episode']:
            raise FrameSyncError('the sim started another episode under this env: is a second '
                                 f'client using the sim in {self.client.where}?')
        self._accept(frame)
        self.step_count += 1
        event = str(frame.event['event'])
        distance = float(frame.event['distance'])
        terms = reward_terms(self.previous_distance, distance, event, self.config)
        self.previous_distance = distance
        terminated = event in ('goal', 'collision')
        truncated = not terminated and self.step_count >= self.config.max_episode_steps
        info: dict[str, Any] = {
            'action_name': ACTION_NAMES[index], 'event': event, 'distance': distance,
            'reward_terms': terms, 'pose': frame.pose, 'step': self.step_count,
            'physics_steps': frame.event['physics_steps'], 'is_success': event == 'goal',
            'path_length': frame.event['path_length'],
            # wheel speeds the sim reports at the end of the period (0 after goal/collision)
            'wheels': [float(frame.event['wheel_left']), float(frame.event['wheel_right'])],
        }
        if terminated or truncated:
            self._episode_over = True
            info['wheels_after_stop'] = self.stop_motors()
        return self._observation, float(sum(terms.values())), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode == 'rgb_array':
            return None if self._rgb is None else self._rgb.copy()
        return None

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        self._stop_sim()
        super().close()

    # --- helpers --------------------------------------------------------------------------
    def stop_motors(self) -> list[float]:
        """Stop the robot (episode boundaries); returns the wheel speeds the sim reports."""
        return self.client.stop()

    def _accept(self, frame: Frame) -> None:
        self._frame = frame
        self._obs, self._rgb = image_msg_to_observation(frame.image)

    @property
    def _observation(self) -> np.ndarray:
        return self._obs.copy()

    def _validate_action(self, action: Any) -> int:
        value = action
        if isinstance(value, np.ndarray):
            if value.size != 1:
                raise InvalidActionError(f'expected one action, got an array of shape '
                                         f'{value.shape}')
            value = value.reshape(()).item()
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise InvalidActionError(f'action must be an integer in {{0, 1, 2}} '
                                     f'(left, forward, right), got {action!r}')
        if not 0 <= int(value) < len(ACTION_NAMES):
            raise InvalidActionError(f'action {int(value)} is outside Discrete(3): use 0 left, '
                                     '1 forward, 2 right')
        return int(value)

    def _stop_sim(self) -> None:
        if self._sim_process is not None:
            self._sim_process.stop()
            self._sim_process = None

    def __del__(self) -> None:  # never leave a sim process behind
        try:
            self._stop_sim()
        except Exception:
            pass


def _sim_answers(client: SimClient, probe_timeout: float) -> bool:
    try:
        client.wait_for_sim(probe_timeout)
    except SimUnavailableError:
        return False
    return True
