"""Command-line helpers shared by the nav_gym commands: env options and readable errors."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from nav_gym.config import SIM_MODES, EnvConfig
from nav_gym.errors import NavGymError
from nav_sim.errors import NavSimError


def add_env_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--namespace', default='', help='ROS namespace of the sim node')
    parser.add_argument('--sim', choices=SIM_MODES, default='auto',
                        help="attach to a running sim, start one ('embedded'), or 'auto'")
    parser.add_argument('--sim-timeout', type=float, default=5.0,
                        help='seconds to wait for the sim before failing')


def env_config(args: argparse.Namespace, **extra: Any) -> EnvConfig:
    return EnvConfig(namespace=args.namespace, sim=args.sim, sim_timeout=args.sim_timeout,
                     **extra)


def strip_ros_args(argv: list[str] | None) -> list[str]:
    """The command's own arguments: drop a trailing ``--ros-args ...`` block (ros2 run passes
    it through)."""
    args = list(sys.argv[1:] if argv is None else argv)
    return args[:args.index('--ros-args')] if '--ros-args' in args else args


def run_command(name: str, body: Callable[[], int]) -> None:
    """Run a command body: readable one-line errors, exit 130 on Ctrl-C, never a traceback."""
    try:
        code = body()
    except (NavGymError, NavSimError) as exc:
        print(f'{name}: error: {exc}', file=sys.stderr)
        code = 1
    except KeyboardInterrupt:
        print(f'{name}: interrupted', file=sys.stderr)
        code = 130
    sys.exit(code)
