"""A stop request by signal: SIGINT or SIGTERM set a flag (no rclpy).

A handler that only notes the signal interrupts nothing mid-way (no exception inside a DDS
call); the command or node looks at the flag between short waits and stops cleanly, doing what
must come before the exit (finishing a bag, sending the robot a zero velocity).
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """Set by SIGINT/SIGTERM; a flag, so the handler can interrupt nothing mid-way."""

    def __init__(self) -> None:
        """Start with no signal received."""
        self.signal_name: str | None = None

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        """Note the signal's name (the signal handler)."""
        self.signal_name = signal.Signals(signum).name

    def __bool__(self) -> bool:
        """Tell whether a stop signal has arrived."""
        return self.signal_name is not None


@contextmanager
def stop_on_signals(stop: StopRequest) -> Iterator[StopRequest]:
    """Let SIGINT and SIGTERM set ``stop`` within the block; restore the handlers after it."""
    previous = {sig: signal.signal(sig, stop) for sig in STOP_SIGNALS}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
