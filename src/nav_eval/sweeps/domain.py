"""Host-local reservation of a ROS domain id (no ROS import).

Processes that each need a DDS domain of their own on one machine (the trials of a sweep, test
runs) reserve one the way ROS's ``domain_coordinator`` (launch_testing / ``ros2 test``) does: by
binding the TCP port ``22119 + domain_id`` on this host.  Only one socket can hold a port, so
the id is unique among everything on the host that coordinates this way, ROS's own tools
included; the kernel releases it when the holder closes it or dies (even by SIGKILL), so a crash
never leaks a reservation.
"""

from __future__ import annotations

import os
import random
import socket
from collections.abc import Sequence

from nav_eval.errors import NavEvalError

PORT_BASE = 22119  # domain_coordinator's: reservations interoperate with `ros2 test`
DOMAIN_IDS = tuple(range(1, 101))  # domain_coordinator's range, clear of the default 0
#: also valid on Linux (their DDS ports stay below 65536 and clear of the ephemeral range) and
#: outside the range that ROS's own tools and our test runs reserve from (``DOMAIN_IDS``)
HIGH_DOMAIN_IDS = tuple(range(215, 233))


class DomainUnavailableError(NavEvalError, RuntimeError):
    """Every domain id of the range is held by another process on this host."""


class DomainReservation:
    """A ROS domain id held for as long as this object is open (a bound port)."""

    def __init__(self, domain_id: int, sock: socket.socket) -> None:
        """Hold ``domain_id`` through the bound socket ``sock``."""
        self.domain_id = domain_id
        self._socket: socket.socket | None = sock

    def environment(self, base: dict[str, str] | None = None) -> dict[str, str]:
        """Return a process environment that uses this domain with localhost discovery."""
        env = dict(os.environ if base is None else base)
        env['ROS_DOMAIN_ID'] = str(self.domain_id)
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        return env

    def release(self) -> None:
        """Give the id back (idempotent)."""
        if self._socket is not None:
            self._socket.close()
            self._socket = None

    def __enter__(self) -> DomainReservation:
        """Use the reservation as a context manager."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Release the id."""
        self.release()


def reserve_domain(ids: Sequence[int] = DOMAIN_IDS,
                   rng: random.Random | None = None) -> DomainReservation:
    """Reserve a free domain id of this host among ``ids``, trying them from a random one."""
    ids = list(ids)
    start = (rng or random.Random()).randrange(len(ids))
    for domain_id in ids[start:] + ids[:start]:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            sock.bind(('', PORT_BASE + domain_id))
        except OSError:
            sock.close()
            continue
        return DomainReservation(domain_id, sock)
    raise DomainUnavailableError(
        f'all ROS domain ids {min(ids)}-{max(ids)} are reserved on this host (TCP ports '
        f'{PORT_BASE + min(ids)}-{PORT_BASE + max(ids)} are bound); run fewer trials at once '
        'on this machine')


def reserve_any_domain() -> DomainReservation:
    """Reserve a domain id, preferring 215..232 (clear of the ids test runs reserve)."""
    try:
        return reserve_domain(HIGH_DOMAIN_IDS)
    except DomainUnavailableError:
        return reserve_domain(DOMAIN_IDS)
