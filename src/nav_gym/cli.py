"""Command-line helpers of every visnav command (nav_gym's and nav_eval's): options, errors.

Each command strips the ``--ros-args`` blocks ``ros2 run`` passes, and runs its body through
:func:`run_command`, the last line of defence: any :class:`nav_sim.errors.VisnavError` is one
line per problem, and so is an unexpected exception from a library (its traceback shows with
``VISNAV_DEBUG=1``).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import Any

from nav_gym.env.config import SIM_MODES, EnvConfig, parse_mapping
from nav_sim.errors import VisnavError, describe_exception, is_interrupt

#: the env settings that say how to reach the sim, as options of every command that does
ENV_OPTIONS = ('namespace', 'sim', 'sim_timeout')


def add_env_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options that say how to reach the sim (EnvConfig's defaults and descriptions)."""
    fields = {f.name: f for f in dataclasses.fields(EnvConfig)}
    for name in ENV_OPTIONS:
        field = fields[name]
        parser.add_argument('--' + name.replace('_', '-'), type=type(field.default),
                            default=field.default, help=field.metadata['help'],
                            **({'choices': SIM_MODES} if name == 'sim' else {}))
    parser.add_argument('--sim-params', default='{}',
                        help="sim parameters for a sim the command starts, as JSON/YAML, e.g. "
                        "'{world: rooms.xml}' (docs/worlds.md)")


def env_config(args: argparse.Namespace, **extra: Any) -> EnvConfig:
    """Return the EnvConfig of the env options (and ``extra`` settings)."""
    return EnvConfig(**{name: getattr(args, name) for name in ENV_OPTIONS},
                     sim_params=parse_mapping(args.sim_params, '--sim-params'), **extra)


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


#: set to 1 to see the traceback behind a command's one-line error
DEBUG_ENV = 'VISNAV_DEBUG'


def run_command(name: str, body: Callable[[], int]) -> None:
    """Run a command body: readable one-line errors, exit 130 on Ctrl-C, never a traceback.

    Unless ``VISNAV_DEBUG=1``, which prints the traceback of an error before its line.
    """
    debug = os.environ.get(DEBUG_ENV, '') not in ('', '0')
    try:
        code = body()
    except VisnavError as exc:  # one line per problem (a world's violations: one each)
        if debug:
            traceback.print_exc()
        for line in str(exc).splitlines() or ['']:
            print(f'{name}: error: {line}', file=sys.stderr)
        code = 1
    except KeyboardInterrupt:
        print(f'{name}: interrupted', file=sys.stderr)
        code = 130
    except OSError as exc:  # a file the command needs cannot be read or written
        if debug:
            traceback.print_exc()
        print(f'{name}: error: {exc}', file=sys.stderr)
        code = 1
    except Exception as exc:  # noqa: BLE001 - the last line of defence: one line, not a trace
        if debug:
            traceback.print_exc()
        if is_interrupt(exc):  # a Ctrl-C that a C extension reported as another error
            print(f'{name}: interrupted', file=sys.stderr)
            code = 130
        else:
            print(f'{name}: error: unexpected {describe_exception(exc)} (a bug: please report '
                  f'it with the traceback that {DEBUG_ENV}=1 shows)', file=sys.stderr)
            code = 1
    sys.exit(code)


def stop_on_sigterm() -> None:
    """Handle SIGTERM as Ctrl-C from now on (a stopped run saves a checkpoint and exits 130).

    For the commands that train or evaluate: ``kill``, a Ray worker's end or a closing
    terminal stop them as Ctrl-C does, with the same cleanup.  Only the first SIGTERM does:
    the process is stopping, and a later one must not cut the checkpoint it saves.  A sweep's
    trial gets several as Ray's processes end (its parent death signal again for each ancestor
    that ends), and the second one used to land in the middle of that save.
    """
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)


def _raise_keyboard_interrupt(signum: int, frame: Any) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # stopping already (see stop_on_sigterm)
    raise KeyboardInterrupt
