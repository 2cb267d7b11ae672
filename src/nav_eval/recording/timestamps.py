"""When each recorded message goes into the bag: the recorder's timestamp policy (pure Python).

Bag timestamps are sim time, so a recording of a seeded run is reproducible:

- a *stamped* message (a header stamp, or the Clock's value) goes at its own stamp, and the
  newest such stamp is the *sim time* so far;
- an *unstamped* one (``cmd_vel``, annotations) goes at the sim time so far.  Unstamped
  messages that come before any sim stamp are *held* until the first one arrives and then go
  at it; if none comes within ``hold_s`` seconds of the first held message, or ``hold_max``
  messages are waiting, they go at their arrival (wall-clock) times, and so does every later
  unstamped message;
- a *paused* recording (``start_ns``) only notes what comes before its start: a stamped
  message stamped earlier, and an unstamped one while the sim time is earlier, are not
  written (but :meth:`StampPolicy.newest` sees the stamps noted);
- timestamps never decrease within a topic: a message never goes before the last one written
  on its topic.

:class:`StampPolicy` takes messages (a topic key, the bytes, the stamp or None) and returns
what to write and when; the clock is injectable, so all of this is tested without ROS.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable
from typing import Any

HOLD_S = 10.0     # unstamped messages wait this long for a first sim stamp ...
HOLD_MAX = 1000   # ... or until this many are waiting
NEVER = 2**63     # the start stamp of a paused recording

#: one message to write: (topic key, bag timestamp in ns, the message's bytes)
Placed = tuple[Hashable, int, Any]


class StampPolicy:
    """Decide every recorded message's bag timestamp (see the module docstring)."""

    def __init__(self, paused: bool = False, clock: Callable[[], int] = time.time_ns,
                 hold_s: float = HOLD_S, hold_max: int = HOLD_MAX) -> None:
        """Start a recording (``paused``: write nothing until :meth:`start`).

        ``clock`` returns wall-clock nanoseconds: the arrival time of a held message.
        """
        self.clock = clock
        self.hold_ns = int(hold_s * 1_000_000_000)
        self.hold_max = hold_max
        self.start_ns = NEVER if paused else 0
        self.sim_ns: int | None = None  # the newest stamp written: the sim time so far
        self.wall_clock = False         # no sim stamp in time: unstamped ones go at arrival
        self._held: list[tuple[Hashable, Any, int]] = []
        self._last: dict[Hashable, int] = {}    # the last timestamp written, per topic
        self._newest: dict[Hashable, int] = {}  # the newest stamp noted, per topic

    def start(self, from_ns: int) -> None:
        """Write messages stamped ``from_ns`` or later from now on (a paused recording)."""
        self.start_ns = from_ns

    def newest(self, key: Hashable) -> int:
        """Return the newest stamp noted on a topic, written or not (-1: none yet)."""
        return self._newest.get(key, -1)

    def place(self, key: Hashable, data: Any, stamp_ns: int | None) -> list[Placed]:
        """Take one message; return what to write now (it, held ones, or nothing)."""
        if self.start_ns and self._before_start(key, stamp_ns):
            return []
        if stamp_ns is None:
            if self.sim_ns is None and not self.wall_clock:
                return self._hold(key, data)
            return [self._at(key, self.clock() if self.wall_clock else self.sim_ns, data)]
        out = []
        if self.sim_ns is None:
            self.sim_ns = stamp_ns
            out = self._release(stamp_ns)
        self.sim_ns = max(self.sim_ns, stamp_ns)
        out.append(self._at(key, stamp_ns, data))
        self._newest[key] = max(stamp_ns, self._newest.get(key, 0))
        return out

    def flush(self) -> list[Placed]:
        """Return the messages still held (at their arrival times): the recording ends."""
        return self._release(None)

    def _before_start(self, key: Hashable, stamp_ns: int | None) -> bool:
        if stamp_ns is None:
            return self.sim_ns is None or self.sim_ns < self.start_ns
        if stamp_ns >= self.start_ns:
            return False
        self._newest[key] = max(stamp_ns, self._newest.get(key, 0))
        return True

    def _at(self, key: Hashable, when: int, data: Any) -> Placed:
        when = max(when, self._last.get(key, 0))  # monotonic per topic
        self._last[key] = when
        return key, when, data

    def _hold(self, key: Hashable, data: Any) -> list[Placed]:
        self._held.append((key, data, self.clock()))
        if (len(self._held) >= self.hold_max
                or self._held[-1][2] - self._held[0][2] > self.hold_ns):
            self.wall_clock = True
            return self._release(None)
        return []

    def _release(self, stamp_ns: int | None) -> list[Placed]:
        """Place the held messages at ``stamp_ns``, or at their arrival times if None."""
        out = [self._at(key, arrival if stamp_ns is None else stamp_ns, data)
               for key, data, arrival in self._held]
        self._held.clear()
        return out
