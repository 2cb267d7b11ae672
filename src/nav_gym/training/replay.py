"""Proportional prioritized replay (``prioritized_replay``) over SB3's n-step replay buffer.

With memory, over the frame-stack buffer (:class:`PrioritizedFrameStackReplayBuffer`): the
priorities are the transitions', the stacks rebuilt as that buffer does.  Its own module for the
learner's size; checkpoints and buffers pickled before name its classes in
:mod:`nav_gym.training.learner`, which imports them, so they load as before.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples

from nav_gym.training.aux_depth import DepthTargets
from nav_gym.training.memory import FrameStackReplayBuffer

PRIORITY_EPS = 1e-6  # added to |TD error| so that no transition's priority is zero


class SumTree:
    """Priorities in a binary sum tree: O(log n) updates and proportional sampling, vectorised."""

    def __init__(self, capacity: int) -> None:
        """Hold ``capacity`` priorities, all zero."""
        self.capacity = capacity
        self.depth = max(capacity - 1, 0).bit_length()
        self.leaves = 1 << self.depth
        self.tree = np.zeros(2 * self.leaves, dtype=np.float64)

    @property
    def total(self) -> float:
        """Return the sum of all priorities."""
        return float(self.tree[1])

    def get(self, indices: np.ndarray) -> np.ndarray:
        """Return the priorities at ``indices``."""
        return self.tree[self.leaves + np.asarray(indices)]

    def set(self, indices: np.ndarray, priorities: np.ndarray) -> None:
        """Set the priorities at ``indices`` (a repeated index keeps its last value)."""
        nodes = self.leaves + np.asarray(indices, dtype=np.int64)
        self.tree[nodes] = priorities
        for _ in range(self.depth):
            nodes = np.unique(nodes // 2)
            self.tree[nodes] = self.tree[2 * nodes] + self.tree[2 * nodes + 1]

    def find(self, masses: np.ndarray) -> np.ndarray:
        """Return the index whose cumulative priority interval holds each of ``masses``."""
        nodes = np.ones(len(masses), dtype=np.int64)
        masses = np.asarray(masses, dtype=np.float64).copy()
        while nodes[0] < self.leaves:
            left = 2 * nodes
            go_right = masses >= self.tree[left]
            masses = np.where(go_right, masses - self.tree[left], masses)
            nodes = np.where(go_right, left + 1, left)
        return np.minimum(nodes - self.leaves, self.capacity - 1)


class PrioritizedReplayBuffer(NStepReplayBuffer):
    """Proportional prioritized replay (Schaul et al. 2016) over SB3's (n-step) replay buffer.

    A new transition gets the largest priority seen so far; a sampled one gets
    ``(|TD error| + eps) ** alpha`` once the learner has its TD error (``update_priorities``).
    ``sample`` draws one index from each of ``batch_size`` equal slices of the total priority
    (stratified, as the paper) and records the indices and the importance weights
    ``(N P(i)) ** -beta``, divided by their largest in the batch, in ``last_indices`` and
    ``last_weights``.  ``n_steps`` 1 is the one-step buffer.
    """

    def __init__(self, *args: Any, alpha: float = 0.6, beta: float = 0.4, n_steps: int = 1,
                 **kwargs: Any) -> None:
        """Create the buffer and its sum tree; ``beta`` is set by the learner as it anneals."""
        super().__init__(*args, n_steps=n_steps, **kwargs)
        if self.n_envs != 1:
            raise ValueError('prioritized replay supports one environment')
        self.alpha, self.beta = alpha, beta
        self.priorities = SumTree(self.buffer_size)
        self.max_priority = 1.0
        self.last_indices = np.zeros(0, dtype=np.int64)
        self.last_weights = np.zeros(0, dtype=np.float32)

    def add(self, *args: Any, **kwargs: Any) -> None:
        """Store a transition with the largest priority so far."""
        index = self.pos
        super().add(*args, **kwargs)
        self.priorities.set(np.array([index]), np.array([self.max_priority ** self.alpha]))

    def sample(self, batch_size: int, env: Any = None) -> ReplayBufferSamples:
        """Sample proportionally to priority; see the class docstring for weights."""
        size = self.buffer_size if self.full else self.pos
        total = self.priorities.total
        bounds = np.linspace(0.0, total, batch_size + 1)
        masses = np.random.uniform(bounds[:-1], bounds[1:])
        indices = np.minimum(self.priorities.find(masses), size - 1)
        probabilities = self.priorities.get(indices) / total
        weights = (size * np.maximum(probabilities, 1e-12)) ** -self.beta
        self.last_indices = indices
        self.last_weights = (weights / weights.max()).astype(np.float32)
        return self._get_samples(indices, env=env)

    def update_priorities(self, indices: np.ndarray, td_errors: np.ndarray) -> None:
        """Set the priorities of sampled transitions from their absolute TD errors."""
        priorities = np.abs(td_errors) + PRIORITY_EPS
        self.max_priority = max(self.max_priority, float(priorities.max()))
        self.priorities.set(indices, priorities ** self.alpha)


class DepthPrioritizedReplayBuffer(DepthTargets, PrioritizedReplayBuffer):
    """Prioritized replay with depth targets."""


class PrioritizedFrameStackReplayBuffer(PrioritizedReplayBuffer, FrameStackReplayBuffer):
    """Prioritized replay of the agent's stacks: single frames stored, stacks sampled."""


class DepthPrioritizedFrameStackReplayBuffer(DepthTargets, PrioritizedFrameStackReplayBuffer):
    """Prioritized replay of the agent's stacks with depth targets."""
