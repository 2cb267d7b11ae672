"""Where a step's time goes: rolling per-step means of named phases (no ROS).

The sim node times each control period (physics, render, message building, publishing, the live
view and the wait for the client's next command); the env times each step (transport wait, image
conversion, live view) and training adds the learner's share (gradient steps, predict).  A
:class:`StepTiming` accumulates seconds per phase and counts steps; every ``interval`` seconds
:meth:`StepTiming.report` returns the window's means per step in milliseconds, the measured
step time (start to start) and steps per second, and starts a new window.  Totals since the
start are kept for ``summary.json``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

REPORT_INTERVAL_S = 1.0


@dataclass
class _Window:
    seconds: dict[str, float] = field(default_factory=dict)
    steps: int = 0
    started: float = 0.0       # perf_counter of the first step start in the window


class StepTiming:
    """Rolling per-step means of named phases, reported about every ``interval`` seconds."""

    def __init__(self, phases: tuple[str, ...], interval: float = REPORT_INTERVAL_S,
                 unit: str = 'step') -> None:
        """Time ``phases`` per ``unit`` (step, period), reporting every ``interval`` s."""
        self.phases = phases
        self.interval = interval
        self.unit = unit
        self._window = _Window()
        self._totals: dict[str, float] = {p: 0.0 for p in phases}
        self._total_steps = 0
        self._total_time = 0.0
        self._last_end: float | None = None
        self._last_report = time.perf_counter()

    def add(self, phase: str, seconds: float) -> None:
        """Add ``seconds`` to ``phase`` in the current window (unknown phases are added)."""
        self._window.seconds[phase] = self._window.seconds.get(phase, 0.0) + seconds
        self._totals[phase] = self._totals.get(phase, 0.0) + seconds

    def step_done(self, now: float | None = None) -> float:
        """Close a step: its time is the time since the previous step closed.

        The first call only sets the reference (what was added before it is dropped), so the
        phases of a window belong to exactly the steps it counts.
        """
        now = time.perf_counter() if now is None else now
        if self._last_end is None:
            self._window = _Window(started=now)
            self._totals = {p: 0.0 for p in self._totals}
            self._last_report = now  # the first report comes a whole interval later
        else:
            self._window.steps += 1
            self._total_steps += 1
            self._total_time += now - self._last_end
        self._last_end = now
        return now

    def since_last_step(self, now: float | None = None) -> float:
        """Seconds since the previous step closed (0 before the first)."""
        now = time.perf_counter() if now is None else now
        return 0.0 if self._last_end is None else now - self._last_end

    def due(self, now: float | None = None) -> bool:
        """Return True when a report is due (``interval`` s since the last, steps in it)."""
        now = time.perf_counter() if now is None else now
        return self._window.steps > 0 and now - self._last_report >= self.interval

    def report(self, now: float | None = None) -> dict[str, float]:
        """Return the window's means per step and start a new window.

        ``<phase>_ms``, ``<unit>_ms`` (the measured step time), ``<unit>s_per_s`` and
        ``<unit>s`` of the steps closed in the window.  Call it right after :meth:`step_done`:
        phases added since then would count in this window.
        """
        now = time.perf_counter() if now is None else now
        window, steps = self._window, max(self._window.steps, 1)
        end = self._last_end if self._last_end is not None else now
        elapsed = end - window.started
        out = {f'{p}_ms': 1e3 * window.seconds.get(p, 0.0) / steps
               for p in (*self.phases, *sorted(set(window.seconds) - set(self.phases)))}
        out[f'{self.unit}_ms'] = 1e3 * elapsed / steps
        out[f'{self.unit}s_per_s'] = window.steps / elapsed if elapsed > 0 else 0.0
        out[f'{self.unit}s'] = window.steps
        self._window = _Window(started=end)
        self._last_report = now
        return out

    def total_seconds(self, phase: str) -> float:
        """Return the seconds spent in ``phase`` since the start."""
        return self._totals.get(phase, 0.0)

    def totals(self) -> dict[str, float]:
        """Means per step since the start (for ``summary.json``), in milliseconds."""
        steps = max(self._total_steps, 1)
        out = {f'{p}_ms': round(1e3 * s / steps, 4) for p, s in self._totals.items()}
        out[f'{self.unit}_ms'] = round(1e3 * self._total_time / steps, 4)
        out[f'{self.unit}s'] = self._total_steps
        return out
