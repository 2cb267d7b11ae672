"""Command-line helpers of every visnav command (nav_gym's and nav_eval's): options, errors.

Each command strips the ``--ros-args`` blocks ``ros2 run`` passes, and runs its body through
:func:`run_command`, which prints any :class:`nav_sim.errors.VisnavError` as one line.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

import yaml

from nav_gym.config import SIM_MODES, EnvConfig
from nav_gym.errors import TrainConfigError
from nav_sim.errors import VisnavError


def add_env_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options that say how to reach the sim (namespace, attach/embedded, time-out)."""
    parser.add_argument('--namespace', default='', help='ROS namespace of the sim node')
    parser.add_argument('--sim', choices=SIM_MODES, default='auto',
                        help="attach to a running sim, start one ('embedded'), or 'auto'")
    parser.add_argument('--sim-timeout', type=float, default=5.0,
                        help='seconds to wait for the sim before failing')
    parser.add_argument('--sim-params', default='{}',
                        help="sim parameters for a sim the command starts, as JSON/YAML, e.g. "
                        "'{world: rooms.xml}' (docs/worlds.md)")


def env_config(args: argparse.Namespace, **extra: Any) -> EnvConfig:
    """Return the EnvConfig of the env options (and ``extra`` settings)."""
    try:
        sim_params = yaml.safe_load(args.sim_params)
    except yaml.YAMLError:
        sim_params = None
    if not isinstance(sim_params, dict):
        raise TrainConfigError(f"--sim-params takes a mapping, e.g. '{{world: rooms.xml}}', "
                               f'got {args.sim_params!r}')
    return EnvConfig(namespace=args.namespace, sim=args.sim, sim_timeout=args.sim_timeout,
                     sim_params=sim_params, **extra)


def strip_ros_args(argv: Sequence[str] | None) -> list[str]:
    """Return the command's own arguments: ``argv`` without its ``--ros-args ... [--]`` blocks.

    ``argv`` defaults to ``sys.argv[1:]``; ``ros2 run`` passes such blocks through and ``--``
    ends one.  The one definition every command uses.
    """
    out: list[str] = []
    inside = False
    for arg in sys.argv[1:] if argv is None else argv:
        if arg == '--ros-args':
            inside = True
        elif inside and arg == '--':
            inside = False
        elif not inside:
            out.append(arg)
    return out


def run_command(name: str, body: Callable[[], int]) -> None:
    """Run a command body: readable one-line errors, exit 130 on Ctrl-C, never a traceback."""
    try:
        code = body()
    except VisnavError as exc:  # one line per problem (a world's violations: one each)
        for line in str(exc).splitlines() or ['']:
            print(f'{name}: error: {line}', file=sys.stderr)
        code = 1
    except KeyboardInterrupt:
        print(f'{name}: interrupted', file=sys.stderr)
        code = 130
    except OSError as exc:  # a file the command needs cannot be read or written
        print(f'{name}: error: {exc}', file=sys.stderr)
        code = 1
    sys.exit(code)
