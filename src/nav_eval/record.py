"""``ros2 run nav_eval record OUTPUT_DIR``: record a running nav_sim graph into an MCAP bag.

Records the nav_sim topics of one namespace (see :mod:`nav_eval.bag_recorder`) until Ctrl-C,
SIGTERM or ``--duration`` seconds, then finishes the bag and prints the messages per topic.
Works with any driver, e.g. a realtime-mode sim teleoperated with ``ros2 topic pub cmd_vel``.
A ``--ros-args ...`` block (``ros2 run`` may pass one) is accepted and ignored: use
``--namespace``.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Sequence
from types import FrameType

from nav_eval.bag_recorder import BagRecorder
from nav_eval.bags import PERIOD_TOPICS
from nav_eval.errors import RecordingError
from nav_gym.cli import strip_ros_args

PROG = 'nav-eval-record'
TICK_S = 0.1
NOTICE_S = 5.0


def positive_seconds(text: str) -> float:
    """Parse a finite duration above zero (an argparse type)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if not 0.0 < value < float('inf'):
        raise argparse.ArgumentTypeError(f'must be a positive number of seconds, got {text}')
    return value


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """Parse the command line of ``nav-eval-record`` (ROS arguments removed)."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Record the nav_sim topics of a namespace into a rosbag2/MCAP '
        'bag until Ctrl-C, SIGTERM or --duration.')
    parser.add_argument('output', metavar='OUTPUT_DIR',
                        help='bag directory to create (must not exist)')
    parser.add_argument('--namespace', default='',
                        help="namespace of the sim node, e.g. /robot1 (default: '/')")
    parser.add_argument('--duration', type=positive_seconds, default=None, metavar='SECONDS',
                        help='stop after this many wall-clock seconds (default: until Ctrl-C)')
    return parser.parse_args(strip_ros_args(argv))


class StopRequest:
    """Set by SIGINT/SIGTERM; a flag, so the handler can interrupt nothing mid-way."""

    def __init__(self) -> None:
        """Start with no signal received."""
        self.signal_name: str | None = None

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        """Note the signal's name (the signal handler)."""
        self.signal_name = signal.Signals(signum).name


def wait_until_stopped(recorder: BagRecorder, stop: StopRequest,
                       duration: float | None) -> None:
    """Sleep in short ticks until a stop signal arrives or ``duration`` seconds pass.

    Says once when the sim's publishers are matched, or after ``NOTICE_S`` that none are, and
    once when a message of every per-period topic has arrived (the sim delivers to the bag).
    """
    where = recorder.namespace or '/'
    start = time.monotonic()
    deadline = None if duration is None else start + duration
    found = hinted = receiving = False
    while stop.signal_name is None:
        if found and not receiving and recorder.wait_for(0, 0.0, PERIOD_TOPICS):
            receiving = True
            print(f'{PROG}: receiving every nav_sim topic of {where}', flush=True)
        if not found and recorder.wait_for_publishers(0.0):
            found = True
            print(f'{PROG}: nav_sim publishers matched in {where}', flush=True)
        elif not (found or hinted) and time.monotonic() - start > NOTICE_S:
            hinted = True
            print(f'{PROG}: no nav_sim publishers in {where} yet (recording anyway); is the '
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


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run nav_eval record`` and the ``nav-eval-record`` script."""
    options = parse_args(sys.argv[1:] if args is None else args)
    stop = StopRequest()
    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            recorder = BagRecorder(options.output, options.namespace, node_name='nav_eval_record')
        except RecordingError as exc:
            raise SystemExit(f'{PROG}: {exc}') from None
        print(f'{PROG}: recording {recorder.namespace or "/"} into {options.output} '
              '(Ctrl-C to stop)', flush=True)
        failure = None
        try:
            wait_until_stopped(recorder, stop, options.duration)
        finally:
            try:
                recorder.close()
            except RecordingError as exc:
                failure = exc
        why = stop.signal_name or f'{options.duration:g} s elapsed'
        print(f'{PROG}: stopped ({why}); messages written to {options.output}:')
        print(format_counts(recorder.counts), flush=True)
        if failure is not None:
            raise SystemExit(f'{PROG}: {failure}')
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


if __name__ == '__main__':
    main()
