"""Specific errors of nav_sim, each saying what to do next."""

from __future__ import annotations


class VisnavError(Exception):
    """Base class of every visnav error: the commands print one as a one-line message."""


class NavSimError(VisnavError):
    """Base class of every nav_sim error."""


class WorldNotFoundError(NavSimError, FileNotFoundError):
    """The MJCF world could not be found in any searched location."""


class ScenarioError(NavSimError, ValueError):
    """A scenario request (seed, split) or a scenario bank is invalid."""


class ConfigError(NavSimError, ValueError):
    """A simulation parameter has an invalid value."""


class EpisodeNotStartedError(NavSimError, RuntimeError):
    """The simulation was stepped before the first reset."""


class SimUnavailableError(NavSimError, TimeoutError):
    """No nav_sim node answered in time, or it disappeared mid-episode."""


class FrameSyncError(NavSimError, RuntimeError):
    """An observation arrived out of order (stale or dropped control periods)."""


class SimConflictError(NavSimError, RuntimeError):
    """More than one sim answers in a namespace, or a new sim would be a second one there.

    Two sims in one namespace mix their worlds: observations and rewards come from both.
    """


class SimInUseError(SimConflictError):
    """Another process controls the sim (resets and steps it): one controlling client at a time."""


class WorldError(NavSimError, ValueError):
    """A world file cannot be read, or breaks the world contract (docs/worlds.md).

    The message has one line per problem, each naming the file and the element.
    """


def describe_exception(exc: BaseException) -> str:
    """Name an exception and its message's first line: ``ValueError: bad value``."""
    lines = str(exc).strip().splitlines()
    return f'{type(exc).__name__}: {lines[0]}' if lines else type(exc).__name__


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a Ctrl-C: a KeyboardInterrupt, or the SystemError that carries one.

    A KeyboardInterrupt that Python's signal handler raises while a C extension's call runs Python
    code (rclpy's ``take_response`` building a service response in an executor's spin) can leave
    the call with a result and the exception set; CPython then raises ``SystemError: <...>
    returned a result with an exception set`` with the interrupt as its cause.  Only that shape:
    an error raised while a Ctrl-C unwinds (its context) is still an error.
    """
    return isinstance(exc, KeyboardInterrupt) or (
        isinstance(exc, SystemError) and isinstance(exc.__cause__, KeyboardInterrupt))
