"""Policies for evaluation: the frozen DQN (deterministic, with its Q-values) and a seeded
uniform-random baseline.  Both only ever see the observation image."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import numpy as np

from nav_eval.errors import EvaluationError


class Policy(Protocol):
    name: str

    def begin_episode(self, seed: int) -> None: ...

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]: ...


class RandomPolicy:
    """Uniform over the three actions, seeded per episode (same seed -> same actions)."""

    name = 'random'

    def __init__(self, actions: int = 3) -> None:
        self.actions = actions
        self._rng = np.random.default_rng(0)

    def begin_episode(self, seed: int) -> None:
        self._rng = np.random.default_rng([7, seed])

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        return int(self._rng.integers(self.actions)), None


class DQNPolicy:
    """A frozen SB3 DQN: ``predict(deterministic=True)``, plus the Q-values it chose from."""

    name = 'dqn'

    def __init__(self, path: str | Path, device: str = 'cpu') -> None:
        self.path = Path(path)
        self.model = load_dqn(self.path, device)

    def begin_episode(self, seed: int) -> None:
        return None

    def q_values(self, observation: np.ndarray) -> np.ndarray:
        import torch
        tensor, _ = self.model.policy.obs_to_tensor(observation)
        with torch.no_grad():
            return self.model.q_net(tensor)[0].cpu().numpy()

    def act(self, observation: np.ndarray) -> tuple[int, list[float] | None]:
        action, _ = self.model.predict(observation, deterministic=True)
        return int(action), [round(float(q), 6) for q in self.q_values(observation)]


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
