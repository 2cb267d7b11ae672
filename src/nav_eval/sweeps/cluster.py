"""Check, before attaching, that this machine can join the Ray cluster at ``HOST:PORT``.

Ray (2.60) authenticates every connection to a cluster with a token when its head runs with
``RAY_AUTH_MODE=token`` (which ``ray start --head`` turns on by itself when a token file exists,
and a local ``ray.init()`` by default).  ``ray.init(address=HOST:PORT)`` from a machine without
the mode or the token retries for about 20 s, printing a ``gcs_client`` warning every second,
and then says only "Failed to connect to Ray cluster"; an address nothing answers on takes
about as long.  :func:`check_cluster` finds both within seconds and says what to set:

1. a TCP connection to ``HOST:PORT`` (nothing listening, no route: the head's address);
2. a GCS client in a child process (Ray's C++ client logs to the process's stderr, which the
   child keeps to itself), which fails at once with ``AuthenticationError`` when the token is
   missing, wrong, or not sent because ``RAY_AUTH_MODE`` is not ``token`` here.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

from nav_eval.errors import SweepError

CONNECT_TIMEOUT_S = 3.0
DEFAULT_TOKEN_FILE = '~/.ray/auth_token'
PROBE_TIMEOUT_S = 20.0
TOKEN_HELP = ("set RAY_AUTH_MODE=token and the head's token (`ray get-auth-token` on the head "
              'prints it) in RAY_AUTH_TOKEN, or in the file RAY_AUTH_TOKEN_PATH names (default '
              '~/.ray/auth_token), here and on every node before `ray start`')
#: run in a child: try a GCS client, print one JSON line
PROBE = """
import json, sys
try:
    import ray
    ray._raylet.GcsClient(address=sys.argv[1])
except Exception as exc:
    kind = 'auth' if type(exc).__name__ == 'AuthenticationError' else type(exc).__name__
    print(json.dumps({'error': kind, 'message': str(exc).splitlines()[0][:300]}))
else:
    print(json.dumps({'error': None}))
"""


def split_address(address: str) -> tuple[str, int]:
    """Return the host and port of ``HOST:PORT``, or raise SweepError."""
    host, _, port = address.rpartition(':')
    if not host or not port.isdigit():
        raise SweepError(f"--address must be 'auto' or HOST:PORT (the head's GCS port, 6379 by "
                         f'default), got {address!r}')
    return host.strip('[]'), int(port)


def token_available() -> bool:
    """Tell whether Ray finds a token here.

    Ray's own order: ``RAY_AUTH_TOKEN``, the file ``RAY_AUTH_TOKEN_PATH`` names, or
    ``~/.ray/auth_token``.
    """
    if os.environ.get('RAY_AUTH_TOKEN', '').strip():
        return True
    path = os.environ.get('RAY_AUTH_TOKEN_PATH') or os.path.expanduser(DEFAULT_TOKEN_FILE)
    try:
        with open(path) as handle:
            return bool(handle.read().strip())
    except OSError:
        return False


def check_cluster(address: str | None) -> None:
    """Raise SweepError (one line, what to do) if the Ray cluster at ``address`` cannot be joined.

    ``None`` (a local Ray of the sweep's own) and ``'auto'`` (the cluster this machine's
    ``ray start`` joined, which Ray finds with its token) are not checked.
    """
    if address is None or address == 'auto':
        return
    host, port = split_address(address)
    if os.environ.get('RAY_AUTH_MODE', '').lower() == 'token' and not token_available():
        raise SweepError(f'RAY_AUTH_MODE=token but this machine has no token for {address}: '
                         f'{TOKEN_HELP}')
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise SweepError(f'no Ray cluster answers at {address} ({exc.strerror or exc}): start '
                         f'its head there with `ray start --head --port={port}`, or check the '
                         'address and the network') from None
    try:
        probe = subprocess.run([sys.executable, '-c', PROBE, address], capture_output=True,
                               text=True, timeout=PROBE_TIMEOUT_S, env=os.environ.copy())
    except subprocess.TimeoutExpired:
        raise SweepError(f'{address} accepts connections but no Ray GCS answered within '
                         f"{PROBE_TIMEOUT_S:g} s: is it the head's GCS port (`ray start --head "
                         '--port=...`)?') from None
    lines = probe.stdout.strip().splitlines()
    if not lines:  # the client died (Ray's C++ checks abort)
        said = probe.stderr.strip().splitlines()
        raise SweepError(f'cannot join the Ray cluster at {address}: the Ray client exited with '
                         f"code {probe.returncode} ({said[0][:200] if said else 'no output'})")
    result = json.loads(lines[-1])
    if result['error'] == 'auth':
        mode = os.environ.get('RAY_AUTH_MODE')
        now = f'RAY_AUTH_MODE is {mode!r}' if mode else 'RAY_AUTH_MODE is not set'
        raise SweepError(f'the Ray cluster at {address} refused this machine (token '
                         f'authentication; {now}): {TOKEN_HELP}')
    if result['error']:
        raise SweepError(f"cannot join the Ray cluster at {address}: {result['error']}: "
                         f"{result.get('message', '')}")
