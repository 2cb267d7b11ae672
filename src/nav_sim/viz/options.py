"""The live view's switch on the command line, ``--live [PORT]``, and its default port.

One definition for every command that can serve the view (nav-sim-demo, nav-gym-train,
nav-eval-evaluate, visnav-pipeline, visnav-demo) and for the sim node's ``live_port``
parameter's documentation.  Imports nothing heavy: a command declares the option without
loading the live view.
"""

from __future__ import annotations

import argparse

#: the port of a live view switched on without one (``--live``): Foxglove's usual port
DEFAULT_PORT = 8765


def add_live_argument(parser: argparse.ArgumentParser, what: str = 'a Foxglove live view',
                      extra: str = '') -> None:
    """Add ``--live [PORT]`` to ``parser``: serve ``what`` on ws://localhost:PORT (off: 0).

    ``extra`` ends the help text (for example what else the switch changes).
    """
    parser.add_argument('--live', nargs='?', type=int, const=DEFAULT_PORT, default=0,
                        metavar='PORT', help=f'serve {what} on ws://localhost:PORT (default '
                        f'port {DEFAULT_PORT}; layout: config/foxglove/visnav.json){extra}')
