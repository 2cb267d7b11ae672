"""Record a running graph until told to stop: a signal, or a duration (no argparse).

What ``nav-eval-record`` does between opening and closing its :class:`BagRecorder`: wait in
short ticks, say once when the sim's publishers are matched (or after a while that none are) and
when every per-period topic arrives, and print the messages per topic at the end.
"""

from __future__ import annotations

import time

from nav_eval.recording.bags import PERIOD_TOPICS
from nav_eval.recording.recorder import BagRecorder
from nav_sim.ros.stop_request import StopRequest

TICK_S = 0.1
NOTICE_S = 5.0


def wait_until_stopped(recorder: BagRecorder, stop: StopRequest,
                       duration: float | None, prog: str) -> None:
    """Sleep in short ticks until a stop signal arrives or ``duration`` seconds pass.

    Says once when the sim's publishers are matched, or after ``NOTICE_S`` that none are, and
    once when a message of every per-period topic has arrived (the sim delivers to the bag).
    """
    where = recorder.namespace
    start = time.monotonic()
    deadline = None if duration is None else start + duration
    found = hinted = receiving = False
    while stop.signal_name is None:
        if found and not receiving and recorder.wait_for(0, 0.0, PERIOD_TOPICS):
            receiving = True
            print(f'{prog}: receiving every nav_sim topic of {where}', flush=True)
        if not found and recorder.wait_for_publishers(0.0):
            found = True
            print(f'{prog}: nav_sim publishers matched in {where}', flush=True)
        elif not (found or hinted) and time.monotonic() - start > NOTICE_S:
            hinted = True
            print(f'{prog}: no nav_sim publishers in {where} yet (recording anyway); is the '
                  'sim running in that namespace (--namespace)?', flush=True)
        left = TICK_S if deadline is None else deadline - time.monotonic()
        if left <= 0.0:
            return
        time.sleep(min(TICK_S, left))


def format_counts(counts: dict[str, int]) -> str:
    """One ``count  topic`` line per topic, then the total."""
    width = max([len(str(n)) for n in counts.values()] + [5])
    lines = [f'{n:>{width}}  {topic}' for topic, n in sorted(counts.items())]
    lines.append(f'{sum(counts.values()):>{width}}  total')
    return '\n'.join(lines)
