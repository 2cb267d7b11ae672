"""``ros2 run nav_eval record OUTPUT_DIR``: record a running nav_sim graph into an MCAP bag.

Records the nav_sim topics of one namespace and the decisions of a policy node there (see
:mod:`nav_eval.recording.recorder`) until Ctrl-C, SIGTERM or ``--duration`` seconds
(:mod:`nav_eval.recording.session`), then finishes the bag and prints the messages per topic.
Works with any driver, e.g. a realtime-mode sim teleoperated with ``ros2 topic pub cmd_vel``.
A ``--ros-args ...`` block (``ros2 run`` may pass one) is accepted and ignored: use
``--namespace``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from nav_eval.errors import RecordingError
from nav_eval.recording.recorder import BagRecorder
from nav_eval.recording.session import format_counts, wait_until_stopped
from nav_eval.recording.topics import WITH_POLICY
from nav_gym.cli import strip_ros_args
from nav_sim.ros.stop_request import StopRequest, stop_on_signals

PROG = 'nav-eval-record'


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
    parser.add_argument('--cmd-vel-stamped', action='store_true',
                        help='record cmd_vel as geometry_msgs/TwistStamped (a sim started with '
                        'cmd_vel_stamped:=true)')
    return parser.parse_args(strip_ros_args(argv))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run nav_eval record`` and the ``nav-eval-record`` script."""
    options = parse_args(sys.argv[1:] if args is None else args)
    with stop_on_signals(StopRequest()) as stop:
        try:
            recorder = BagRecorder(options.output, options.namespace, node_name='nav_eval_record',
                                   topics=WITH_POLICY, cmd_vel_stamped=options.cmd_vel_stamped)
        except RecordingError as exc:
            raise SystemExit(f'{PROG}: {exc}') from None
        print(f'{PROG}: recording {recorder.namespace} into {options.output} '
              '(Ctrl-C to stop)', flush=True)
        failure = None
        try:
            wait_until_stopped(recorder, stop, options.duration, PROG)
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


if __name__ == '__main__':
    main()
