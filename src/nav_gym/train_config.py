"""The old path of the training configuration (now :mod:`nav_gym.training.config`).

Checkpoints saved before the move pickle their learner as ``nav_gym.train_config.LearnerSpec``.
New code imports the new module.
"""

from __future__ import annotations

from nav_gym.training.config import TrainConfig
from nav_gym.training.spec import LearnerSpec

__all__ = ['LearnerSpec', 'TrainConfig']
