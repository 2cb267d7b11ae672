"""Specific errors of nav_eval, each saying what to do next."""

from __future__ import annotations

from nav_gym.errors import NavGymError


class NavEvalError(NavGymError):
    """Base class of every nav_eval error (a NavGymError, so the commands print it cleanly)."""


class EvaluationError(NavEvalError, RuntimeError):
    """An evaluation cannot run: missing run directory or checkpoint, bad seeds or sets."""


class DiagnosisError(NavEvalError, RuntimeError):
    """A failure diagnosis cannot run: no such episode, or no trace/bag to read."""


class RecordingError(NavEvalError, RuntimeError):
    """A bag cannot be written (target exists, writer failure) or the recording failed."""
