"""Policies for evaluation: the learned one and the baselines, on the one acting protocol.

The frozen DQN (deterministic, with its Q-values), a seeded uniform-random baseline and a
scripted visual servo act on the observation image only; for diagnosis, the frozen DQN with
training's final exploration.  The oracle is the one privileged baseline: it follows the true
state (the scenario and the robot's pose) and never sees an image; nothing it computes reaches
the learner or an observation.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.errors import EvaluationError
from nav_gym.env.actions import action_twists
from nav_gym.policy.actors import DQNActor, ServoActor
from nav_sim.core.planner import Planner
from nav_sim.core.scenarios import build_banks, sample_scenario
from nav_sim.core.world import load_arena


class RandomPolicy:
    """Uniform over the three actions, seeded per episode (same seed -> same actions)."""

    name = 'random'

    def __init__(self, actions: int = 3) -> None:
        """Draw from ``actions`` actions."""
        self.actions = actions
        self._rng = np.random.default_rng(0)

    def begin_episode(self, seed: int) -> None:
        """Reseed from the scenario seed."""
        self._rng = np.random.default_rng([7, seed])

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        """Draw an action (the image is ignored)."""
        return int(self._rng.integers(self.actions)), None


#: the servo baseline, as the evaluation names it
ServoPolicy = ServoActor


class DQNPolicy(DQNActor):
    """The frozen DQN of a run's checkpoint, loaded for evaluation (greedy, with Q-values)."""

    def __init__(self, path: str | Path, device: str = 'cpu') -> None:
        """Load the checkpoint at ``path`` onto ``device`` (EvaluationError if it cannot)."""
        self.path = Path(path)
        self.hold(load_dqn(self.path, device))


class ExploringDQNPolicy(DQNPolicy):
    """The frozen DQN acting as it did late in training, with training's final exploration.

    A uniform-random action with probability ``epsilon`` (SB3's epsilon-greedy), seeded per
    episode.  A diagnosis, never the measure of a policy (evaluation is deterministic): where
    it succeeds and the greedy policy times out, the network's Q-values lead to the goal and
    what fails is the frozen policy's cycles, which a few random actions break.
    """

    name = 'explore'

    def __init__(self, path: str | Path, epsilon: float, device: str = 'cpu') -> None:
        """Load the checkpoint at ``path``; act at random with probability ``epsilon``."""
        if not 0.0 <= epsilon <= 1.0:
            raise EvaluationError(f'epsilon must be within [0, 1], got {epsilon!r}')
        super().__init__(path, device)
        self.epsilon = epsilon
        self._rng = np.random.default_rng(0)

    def begin_episode(self, seed: int) -> None:
        """Begin the episode; reseed from the scenario seed (same seed -> same random actions)."""
        super().begin_episode(seed)
        self._rng = np.random.default_rng([11, seed])

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        """Take the greedy action, or with probability epsilon a random one (with the Q-values)."""
        action, q_values = super().act(observation)
        if self._rng.random() < self.epsilon:
            action = int(self._rng.integers(self.model.action_space.n))
            self.carried_out(action)  # a memory's previous action is the one taken
        return action, q_values


def load_dqn(path: Path, device: str = 'cpu') -> Any:
    """Load a DQN checkpoint for inference, or raise EvaluationError saying what to do."""
    import zipfile

    from nav_gym.training.learner import load_checkpoint
    if not path.is_file():
        raise EvaluationError(f'checkpoint {path} not found; train first with '
                              '`ros2 run nav_gym train` or pass --checkpoint')
    try:
        return load_checkpoint(path, device=device)
    except (zipfile.BadZipFile, EOFError, KeyError, ValueError, RuntimeError, OSError,
            AssertionError) as exc:
        raise EvaluationError(f'checkpoint {path} is corrupt or incompatible '
                              f'({type(exc).__name__}: {exc})') from exc


class OraclePolicy:
    """Drive a plan made on the true map with the env's three actions: the task's ceiling.

    A privileged evaluation baseline (:mod:`nav_sim.core.planner`): from the scenario's exact
    layout, start and goal it plans the fewest actions that reach the goal within the episode
    limit, and replans from the robot's true pose whenever the pose is not where the plan put
    it.  It asks how many scenarios the actions, the decision period and the step limit can solve
    at all; where it finds no plan it turns left, and its episode times out.  The runner tells it
    the env's ``info`` after the reset and every step (:meth:`follow`); it ignores the image.
    """

    name = 'oracle'

    def __init__(self, config: Any) -> None:
        """Plan in the world, with the actions and the episode limit, of a TrainConfig."""
        self.geometry, self.sim = load_arena(config.sim_params)
        self.planner = Planner(self.geometry, self.sim, action_twists(config.env_config()))
        self.banks = build_banks(self.sim, self.geometry)
        self.max_steps = config.max_episode_steps
        self.scenario: Any = None
        self.plan: list[int] = []
        self.expected: tuple[float, float, float] | None = None
        self.steps = 0

    def begin_episode(self, seed: int) -> None:
        """Start an episode (the plan comes with the reset's ``info``)."""
        self.scenario, self.plan, self.expected, self.steps = None, [], None, 0

    def follow(self, info: dict[str, Any]) -> None:
        """Take the true state after a reset (the scenario) or a step (the pose)."""
        if 'scenario' in info:  # a reset: the exact scenario from its seed and split
            self.scenario = sample_scenario(info['seed'], info['split'], self.banks,
                                            self.geometry, self.sim)
            self.steps = 0
            self._replan(tuple(info['pose']))
            return
        self.steps = int(info['step'])
        pose = tuple(info['pose'])
        if self.expected is None or not _same_pose(pose, self.expected):
            self._replan(pose)

    def _replan(self, pose: tuple[float, float, float]) -> None:
        sc = self.scenario
        self.plan = self.planner.plan(sc.layout, pose, sc.goal, self.max_steps - self.steps) or []
        self.expected = pose

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        """Take the plan's next action (the image is ignored); left without a plan."""
        if not self.plan or self.expected is None:
            return 0, None
        action = self.plan.pop(0)
        self.expected, _ = self.planner.drive(self.expected, action, self.scenario.layout,
                                              self.scenario.goal)
        return action, None


def _same_pose(a: tuple[float, ...], b: tuple[float, ...], tolerance: float = 1e-6) -> bool:
    """Tell whether two poses agree (positions in m, headings in rad, modulo a turn)."""
    turn = math.remainder(a[2] - b[2], 2.0 * math.pi)
    return abs(a[0] - b[0]) <= tolerance and abs(a[1] - b[1]) <= tolerance and \
        abs(turn) <= tolerance
