"""The old path of the learner's classes (now :mod:`nav_gym.training.learner`), for saved files.

SB3 pickles classes by module path: checkpoints saved before the move name
``nav_gym.learner.DuelingCnnPolicy`` as their policy class and replay buffers saved before it
are ``nav_gym.learner.PrioritizedReplayBuffer`` objects.  New code imports the new module.
"""

from __future__ import annotations

from nav_gym.training.learner import (
    DuelingCnnPolicy,
    DuelingQNetwork,
    Learner,
    PrioritizedReplayBuffer,
    SumTree,
)

__all__ = ['DuelingCnnPolicy', 'DuelingQNetwork', 'Learner', 'PrioritizedReplayBuffer', 'SumTree']
