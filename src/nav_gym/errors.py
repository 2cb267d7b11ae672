"""Specific errors of nav_gym, each saying what to do next."""

from __future__ import annotations

from nav_sim.errors import VisnavError


class NavGymError(VisnavError):
    """Base class of every nav_gym error."""


class InvalidActionError(NavGymError, ValueError):
    """An action outside ``Discrete(3)``."""


class ObservationError(NavGymError, ValueError):
    """A camera image that cannot be turned into an observation."""


class ResetNeededError(NavGymError, RuntimeError):
    """step() was called before reset() or after the episode ended."""


class CheckpointError(NavGymError, RuntimeError):
    """A checkpoint is missing, corrupt or incompatible."""


class TrainConfigError(NavGymError, ValueError):
    """A training configuration value is invalid."""


class PolicyModelError(NavGymError, RuntimeError):
    """The policy node's model cannot be found or read (the message says which and why)."""


class DiskFullError(CheckpointError):
    """A save ran out of disk space (the message names the file and the space it needs)."""


class TrainingError(NavGymError, RuntimeError):
    """Training stopped early (e.g. its sim died) after saving a checkpoint to resume from."""
