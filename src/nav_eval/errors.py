"""Specific errors of nav_eval, each saying what to do next."""

from __future__ import annotations

from nav_sim.errors import VisnavError


class NavEvalError(VisnavError):
    """Base class of every nav_eval error."""


class EvaluationError(NavEvalError, RuntimeError):
    """An evaluation cannot run: missing run directory or checkpoint, bad seeds or sets."""


class DiagnosisError(NavEvalError, RuntimeError):
    """A failure diagnosis cannot run: no such episode, or no trace/bag to read."""


class RecordingError(NavEvalError, RuntimeError):
    """A bag cannot be written (target exists, writer failure) or the recording failed."""


class ReportError(NavEvalError, RuntimeError):
    """The report cannot be written (e.g. the directory is not a run directory)."""


class SweepError(NavEvalError, ValueError):
    """A sweep's settings or directory are not usable (the message says what to change)."""


class TrialFailedError(NavEvalError, RuntimeError):
    """A stage of a sweep trial exited with an error; the message ends with its log's tail."""
