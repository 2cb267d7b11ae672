"""The Gymnasium environment: a ROS 2 client of the ``nav_sim`` node.

Observation: the camera image only, ``Box(0, 255, (3, 84, 84), uint8)``.  Actions:
``Discrete(3)`` = 0 turn left, 1 forward, 2 turn right, sent as ``cmd_vel`` Twists.  Pose, goal,
distance, the scenario and the camera's coarse depth (a training target,
``nav_sim.core.depth``) go to ``info`` and the reward, never to the policy.
"""

from __future__ import annotations

import itertools
import math
import os
import time
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from nav_gym.env.actions import ACTION_NAMES, action_twists
from nav_gym.env.config import EnvConfig
from nav_gym.env.observation import OBS_SHAPE, image_msg_to_observation
from nav_gym.env.reward import reward_terms
from nav_gym.errors import InvalidActionError, ResetNeededError
from nav_sim import interface
from nav_sim.core.config import normalise_split, validate_seed
from nav_sim.core.depth import DEPTH_KEY, parse_depth
from nav_sim.core.events import EVENT_GOAL, TERMINAL_EVENTS
from nav_sim.core.step_timing import StepTiming
from nav_sim.core.world import load_arena
from nav_sim.errors import FrameSyncError, SimConflictError, SimUnavailableError
from nav_sim.ros.client import Frame, SimClient
from nav_sim.ros.process import SimProcess

_instances = itertools.count()
#: where an env step's time goes (on /diagnostics and in summary.json): waiting for the sim's
#: frame (publish cmd_vel, the sim's period, transport), image conversion, the observers (the
#: live view; in evaluation also the bag's scene topics); training adds the learner's
#: ``gradient_step`` and ``predict``
STEP_PHASES = ('transport', 'image', 'live')


class NavigationEnv(gym.Env):
    """Visual navigation through the nav_sim node, one control period per step (lockstep)."""

    metadata = {'render_modes': ['rgb_array'], 'render_fps': 5}

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        """Build the env from ``config`` with keyword ``overrides`` and connect to a sim.

        Depending on ``config.sim`` this attaches to a running sim or starts one; it also
        starts publishing the step budget on /diagnostics.
        """
        super().__init__()
        base = config or EnvConfig()
        self.config = EnvConfig(**{**base.__dict__, **overrides}) if overrides else base
        if render_mode not in (None, 'rgb_array'):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self.observation_space = spaces.Box(0, 255, OBS_SHAPE, np.uint8)
        self.action_space = spaces.Discrete(len(ACTION_NAMES))
        self._actions = action_twists(self.config)
        self._sim_process: SimProcess | None = None
        self._client: SimClient | None = None
        self._frame: Frame | None = None
        self._rgb: np.ndarray | None = None
        self._episode_over = True
        self.step_count = 0
        self.previous_distance = math.nan
        self.timing = StepTiming(STEP_PHASES)
        self.live: Any = None  # a nav_gym.env.live_view.EnvLive after start_live()
        #: told of every reset and step (on_reset, on_step, note_q_values): the live view, a
        #: bag writer of the evaluation; none by default, and then nothing is done
        self.observers: list[Any] = []
        self._connect()
        self._start_diagnostics()

    # --- connection -----------------------------------------------------------------------
    def _connect(self) -> None:
        cfg = self.config
        namespace = cfg.namespace
        if cfg.sim == 'embedded' and not namespace:
            namespace = f'/visnav_env_{os.getpid()}_{next(_instances)}'
        client = SimClient(namespace, timeout=cfg.sim_timeout,
                           node_name=f'visnav_env_{os.getpid()}_{next(_instances)}',
                           cmd_vel_stamped=cfg.cmd_vel_stamped)
        try:
            if cfg.sim == 'attach':
                client.wait_for_sim(cfg.sim_timeout)
            elif cfg.sim == 'auto' and _sim_answers(client, cfg.probe_timeout, cfg.sim_timeout):
                pass
            else:
                if cfg.sim == 'auto' and not namespace:
                    client.close()
                    namespace = f'/visnav_env_{os.getpid()}_{next(_instances)}'
                    client = SimClient(namespace, timeout=cfg.sim_timeout,
                                       node_name=f'visnav_env_{os.getpid()}',
                                       cmd_vel_stamped=cfg.cmd_vel_stamped)
                params = {'publish_clock': False, **cfg.sim_params}
                if cfg.cmd_vel_stamped:  # the default stays unsaid: the workshop's Twist
                    params['cmd_vel_stamped'] = True
                load_arena(params)  # a bad world or setting: its one-line error, raised here
                # never a second sim in a namespace: look for one as long as 'auto' does
                looked = cfg.sim == 'auto' or not cfg.namespace  # or a fresh namespace
                _refuse_occupied(client, client.find_sims(0.0 if looked else cfg.probe_timeout))
                self._sim_process = SimProcess(namespace=namespace, params=params)
                try:
                    client.wait_for_sim(max(cfg.sim_timeout, 30.0), self._sim_process.failure,
                                        self._sim_process.ready)
                except SimConflictError:  # one was there, not yet discovered by the check above
                    _refuse_occupied(client, client.sim_nodes())
                    raise
        except BaseException:
            client.close()
            self.stop_sim()
            raise
        self._client = client

    @property
    def client(self) -> SimClient:
        """Return the sim client; raise SimUnavailableError once the env is closed."""
        if self._client is None:
            raise SimUnavailableError('the environment is closed')
        return self._client

    @property
    def namespace(self) -> str:
        """Return the ROS namespace of the sim this env drives."""
        return self.client.namespace

    @property
    def last_stamp_ns(self) -> int:
        """Sim-time stamp of the latest observation (-1 before the first reset)."""
        return -1 if self._frame is None else self._frame.stamp_ns

    # --- Gymnasium API --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode of the seeded scenario; return its first observation and info."""
        options = options or {}
        scenario_seed = options.get('scenario_seed', seed)
        for value in (seed, scenario_seed):
            if value is not None:
                validate_seed(value)  # the seeds the sim takes: [0, 2**63)
        super().reset(seed=seed)
        self.stop_motors()
        split = normalise_split(options.get('split', self.config.split))
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
        _add_depth(info, frame)
        for observer in self.observers:
            observer.on_reset(frame.stamp_ns, self._rgb, self._obs, info)
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Act for one control period; return observation, reward, terminated, truncated, info."""
        index = self._validate_action(action)
        if self._episode_over or self._frame is None:
            raise ResetNeededError('the episode is over (or never started): call reset() first')
        linear, angular = self._actions[index]
        start = time.perf_counter()
        frame = self.client.step(linear, angular, self._frame)
        received = time.perf_counter()
        if frame.event['episode'] != self._frame.event['episode']:
            self.client.check_single_sim()  # a second sim is the other likely cause: say so
            raise FrameSyncError('the sim started another episode under this env: is a second '
                                 f'client using the sim in {self.client.where}?')
        self._accept(frame)
        self.timing.add('transport', received - start)
        self.timing.add('image', time.perf_counter() - received)
        self.step_count += 1
        event = str(frame.event['event'])
        distance = float(frame.event['distance'])
        terms = reward_terms(self.previous_distance, distance, event, self.config)
        self.previous_distance = distance
        terminated = event in TERMINAL_EVENTS
        truncated = not terminated and self.step_count >= self.config.max_episode_steps
        info: dict[str, Any] = {
            'action_name': ACTION_NAMES[index], 'event': event, 'distance': distance,
            'reward_terms': terms, 'pose': frame.pose, 'step': self.step_count,
            'physics_steps': frame.event['physics_steps'], 'is_success': event == EVENT_GOAL,
            'path_length': frame.event['path_length'],
            # wheel speeds the sim reports at the end of the period (0 after goal/collision)
            'wheels': [float(frame.event['wheel_left']), float(frame.event['wheel_right'])],
        }
        _add_depth(info, frame)
        if terminated or truncated:
            self._episode_over = True
            info['wheels_after_stop'] = self.stop_motors()
        reward = float(sum(terms.values()))
        if self.observers:
            start = time.perf_counter()
            for observer in self.observers:
                observer.on_step(frame.stamp_ns, self._rgb, self._obs, index, reward, info,
                                 terminated or truncated)
            self.timing.add('live', time.perf_counter() - start)
        self._step_timed()
        return self._observation, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """Return a copy of the latest camera image in 'rgb_array' mode, else None."""
        if self.render_mode == 'rgb_array':
            return None if self._rgb is None else self._rgb.copy()
        return None

    def sim_failure(self) -> str | None:
        """Return why the sim this env started exited (exit code and log tail).

        None while it runs or when the env attached to a sim it did not start.
        """
        return None if self._sim_process is None else self._sim_process.failure()

    # --- live view and time budget -----------------------------------------------------------
    def start_live(self, port: int) -> str:
        """Serve this env's live view on ``port`` (Foxglove); returns its ``ws://`` URL."""
        from nav_gym.env.live_view import EnvLive
        if self.live is None:
            self.live = EnvLive(port, self.config.sim_params)
            self.observers.append(self.live)
        return self.live.url

    def note_q_values(self, q_values: Any) -> None:
        """Attach the policy's Q-values to the next step for the observers (evaluation)."""
        for observer in self.observers:
            observer.note_q_values(q_values)

    def _start_diagnostics(self) -> None:
        """Publish the env's step budget on /diagnostics; read its sim's from there."""
        from diagnostic_msgs.msg import DiagnosticArray
        node = self.client.node
        self._pub_diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._sim_status = f'{node.resolve_topic_name(interface.NODE_NAME)}: control period'
        self._sim_sums: dict[str, float] = {}
        node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name == self._sim_status:
                values = {kv.key: float(kv.value) for kv in status.values}
                periods = values.get('periods', 0.0)
                for key, value in values.items():
                    if key.endswith('_ms'):
                        self._sim_sums[key] = self._sim_sums.get(key, 0.0) + value * periods
                self._sim_sums['periods'] = self._sim_sums.get('periods', 0.0) + periods

    def _step_timed(self) -> None:
        timing = self.timing
        now = timing.step_done()
        if not timing.due(now):
            return
        from rclpy.serialization import serialize_message

        from nav_sim.ros import messages as ros_msgs
        report = timing.report(now)
        msg = ros_msgs.diagnostics_msg(
            f'{self.client.node.get_fully_qualified_name()}: env step',
            f"{report['steps_per_s']:.1f} steps/s", report,
            ros_msgs.stamp_from_ns(self.last_stamp_ns), hardware_id='nav_gym')
        self._pub_diagnostics.publish(msg)
        if self.live is not None:
            self.live.log_diagnostics(serialize_message(msg))

    def time_budget(self) -> dict[str, Any]:
        """Return the mean milliseconds per step since the start.

        The env's phases (and the learner's, if training added them) and its sim's control
        period phases, read from the sim's /diagnostics.
        """
        sums = self._sim_sums
        periods = sums.get('periods', 0.0)
        sim = ({k: round(v / periods, 4) for k, v in sums.items() if k.endswith('_ms')}
               if periods else {})
        return {'env_step': self.timing.totals(), 'sim_period': {**sim, 'periods': periods}}

    def close(self) -> None:
        """Stop the live view, the client and a sim this env started."""
        if self.live is not None:
            self.observers.remove(self.live)
            self.live.close()
            self.live = None
        if self._client is not None:
            self._client.close()
            self._client = None
        self.stop_sim()
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

    def stop_sim(self) -> None:
        """Stop the sim this env started (nothing if it attached); safe from another thread."""
        if self._sim_process is not None:
            self._sim_process.stop()
            self._sim_process = None

    def __del__(self) -> None:  # never leave a sim process behind
        """Stop a sim this env started, ignoring any error."""
        try:
            self.stop_sim()
        except Exception:
            pass


def _add_depth(info: dict[str, Any], frame: Frame) -> None:
    """Put the frame's coarse depth in ``info`` (``nav_sim.core.depth``): a training target."""
    text = frame.event.get(DEPTH_KEY)
    if text is not None:
        info[DEPTH_KEY] = parse_depth(text)


def _sim_answers(client: SimClient, probe_timeout: float, sim_timeout: float) -> bool:
    """Tell whether a sim answers in the client's namespace ('auto' then attaches to it).

    A sim that is seen but not yet ready within ``probe_timeout`` gets ``sim_timeout`` more:
    'auto' never starts a second sim into a namespace; several sims raise SimConflictError.
    """
    try:
        client.wait_for_sim(probe_timeout)
    except SimUnavailableError:
        if not client.sim_nodes():
            return False
        client.wait_for_sim(sim_timeout)
    return True


def _refuse_occupied(client: SimClient, names: list[str]) -> None:
    """Raise SimConflictError if the namespace an env is to start its own sim in has one."""
    if names:
        raise SimConflictError(
            f"{client.where} already has a nav_sim ({', '.join(names)}): not starting a second "
            "one there; use sim='attach' (or 'auto') to drive it, or choose another namespace")
