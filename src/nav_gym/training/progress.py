"""Progress lines for a training whose output is a log, not a terminal (light imports only).

A terminal gets SB3's progress bar.  A log (a sweep trial's, ``nohup``'s) gets one line every
few minutes instead, so that the hour between two checkpoints is not silent.  One line reads
"progress: step 110,000 of 200,000 (55 %), 19.4 steps/s, 1 h 17 min to go; last 100
episodes: success 74 %, mean return +3.21".
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

PROGRESS_EVERY_S = 300.0


def duration(seconds: float) -> str:
    """Return a duration to the minute: '1 h 17 min', '4 min', 'under a minute'."""
    minutes = round(seconds / 60)
    if minutes < 1:
        return 'under a minute'
    hours, minutes = divmod(minutes, 60)
    return f'{hours} h {minutes} min' if hours else f'{minutes} min'


def progress_line(steps: int, total: int, rate: float, returns: Sequence[float],
                  successes: Sequence[bool]) -> str:
    """Return one progress line.

    ``rate`` is this session's steps per second (0: not known yet); ``returns`` and
    ``successes`` are the recent episodes' (SB3's rolling window, possibly empty).
    """
    share = f' ({100 * steps / total:.0f} %)' if total > 0 else ''
    line = f'progress: step {steps:,} of {total:,}{share}'
    if rate > 0:
        line += f', {rate:.1f} steps/s, {duration(max(total - steps, 0) / rate)} to go'
    if not returns:
        return line + '; no episode has ended yet'
    line += '; last episode:' if len(returns) == 1 else f'; last {len(returns)} episodes:'
    if successes:
        line += f' success {100 * sum(map(bool, successes)) / len(successes):.0f} %,'
    return line + f' mean return {sum(returns) / len(returns):+.2f}'


def progress_callback(total_timesteps: int, every_s: float = PROGRESS_EVERY_S,
                      clock: Callable[[], float] = time.monotonic,
                      write: Callable[[str], Any] = lambda line: print(line, flush=True)) -> Any:
    """Return an SB3 callback that writes :func:`progress_line` every ``every_s`` seconds."""
    from stable_baselines3.common.callbacks import BaseCallback

    class ProgressLines(BaseCallback):
        """One line every ``every_s`` seconds of training: the step, the rate, the episodes."""

        def _on_training_start(self) -> None:
            self.started, self.steps_before = clock(), self.num_timesteps
            self.due = self.started + every_s

        def _on_step(self) -> bool:
            now = clock()
            if now >= self.due:
                self.due = now + every_s
                elapsed = now - self.started
                rate = (self.num_timesteps - self.steps_before) / elapsed if elapsed > 0 else 0.0
                write(progress_line(self.num_timesteps, total_timesteps, rate,
                                    [info['r'] for info in self.model.ep_info_buffer],
                                    list(self.model.ep_success_buffer)))
            return True

    return ProgressLines()
