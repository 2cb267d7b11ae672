"""Policies for evaluation, each acting on the observation image only.

The frozen DQN (deterministic, with its Q-values), a seeded uniform-random baseline and a
scripted visual servo; for diagnosis, the frozen DQN with training's final exploration.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from nav_eval.analysis.failure_layers import centre_band, goal_bearing, servo_action
from nav_eval.errors import EvaluationError


class Policy(Protocol):
    """What evaluation needs of a policy: a name, an episode start and an action per image."""

    name: str

    def begin_episode(self, seed: int) -> None:
        """Prepare for the episode of scenario ``seed``."""
        ...

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        """Choose an action for an observation; also return Q-values if the policy has them."""
        ...


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


class ServoPolicy:
    """Turn toward the green goal pixels, drive when they are centred, else turn left.

    A scripted image-only baseline, the probe of docs/experiments.md: it asks whether the task
    is solvable from single images, and it measures how hard a scenario bank is without any
    learning.
    """

    name = 'servo'

    def __init__(self, band: float = 0.3) -> None:
        """Drive when the goal centroid is within ``band`` of the image centre (-1..1 units)."""
        self.band = band

    @classmethod
    def for_actions(cls, turn_rate: float, control_period: float,
                    hfov_deg: float) -> ServoPolicy:
        """Make a servo whose 'centred' band fits one turn step of these actions and camera."""
        return cls(centre_band(turn_rate * control_period, math.radians(hfov_deg)))

    def begin_episode(self, seed: int) -> None:
        """Start an episode (the servo keeps no state)."""
        return None

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        """Steer toward the goal's bearing in the image; turn left while it is not in view."""
        action = servo_action(goal_bearing(observation), self.band)
        return (0 if action is None else action), None


class DQNPolicy:
    """A frozen SB3 DQN: ``predict(deterministic=True)``, plus the Q-values it chose from."""

    name = 'dqn'

    def __init__(self, path: str | Path, device: str = 'cpu') -> None:
        """Load the checkpoint at ``path`` onto ``device``."""
        self.path = Path(path)
        self.model = load_dqn(self.path, device)

    def begin_episode(self, seed: int) -> None:
        """Start an episode (the frozen network keeps no state)."""
        return None

    def q_values(self, observation: np.ndarray) -> np.ndarray:
        """Return the network's Q-value of every action for one observation."""
        import torch
        tensor, _ = self.model.policy.obs_to_tensor(observation)
        with torch.no_grad():
            return self.model.q_net(tensor)[0].cpu().numpy()

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        """Take the greedy action; also return the Q-values it was chosen from."""
        action, _ = self.model.predict(observation, deterministic=True)
        return int(action), [round(float(q), 6) for q in self.q_values(observation)]


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
        """Reseed from the scenario seed (same seed -> same random actions)."""
        self._rng = np.random.default_rng([11, seed])

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        """Take the greedy action, or with probability epsilon a random one (with the Q-values)."""
        action, q_values = super().act(observation)
        if self._rng.random() < self.epsilon:
            action = int(self._rng.integers(self.model.action_space.n))
        return action, q_values


def load_dqn(path: Path, device: str = 'cpu') -> Any:
    """Load a DQN checkpoint for inference, or raise EvaluationError saying what to do."""
    import zipfile

    from stable_baselines3 import DQN
    if not path.is_file():
        raise EvaluationError(f'checkpoint {path} not found; train first with '
                              '`ros2 run nav_gym train` or pass --checkpoint')
    try:
        return DQN.load(path, device=device)
    except (zipfile.BadZipFile, EOFError, KeyError, ValueError, RuntimeError, OSError,
            AssertionError) as exc:
        raise EvaluationError(f'checkpoint {path} is corrupt or incompatible '
                              f'({type(exc).__name__}: {exc})') from exc
