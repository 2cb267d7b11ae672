"""The sweep's check of a Ray cluster address before it attaches (no Ray started here).

A cluster that refuses this machine's token is tested across two hosts in test_two_hosts.
"""

from __future__ import annotations

import time

import pytest

from helpers import free_port
from nav_eval.errors import SweepError
from nav_eval.sweeps.cluster import check_cluster, token_available


@pytest.mark.parametrize('address', ['localhost', 'host:port', ':6379'])
def test_an_address_that_is_not_host_and_port_is_refused(address):
    with pytest.raises(SweepError, match="--address must be 'auto' or HOST:PORT"):
        check_cluster(address)


def test_a_local_ray_and_auto_are_not_checked():
    check_cluster(None)
    check_cluster('auto')


def test_nothing_listening_is_one_line_within_seconds():
    port = free_port()
    started = time.monotonic()
    with pytest.raises(SweepError, match=rf'no Ray cluster answers at 127.0.0.1:{port} '
                       r'\(Connection refused\): start its head there with `ray start --head '
                       rf'--port={port}`'):
        check_cluster(f'127.0.0.1:{port}')
    assert time.monotonic() - started < 5.0


def test_token_mode_without_a_token_says_where_to_put_one(monkeypatch, tmp_path):
    monkeypatch.setenv('RAY_AUTH_MODE', 'token')
    monkeypatch.delenv('RAY_AUTH_TOKEN', raising=False)
    monkeypatch.setenv('RAY_AUTH_TOKEN_PATH', str(tmp_path / 'absent'))
    assert not token_available()
    with pytest.raises(SweepError, match='RAY_AUTH_MODE=token but this machine has no token '
                       'for 10.0.0.1:6379: .* in RAY_AUTH_TOKEN, or in the file '
                       r'RAY_AUTH_TOKEN_PATH names \(default ~/.ray/auth_token\)'):
        check_cluster('10.0.0.1:6379')
    (tmp_path / 'absent').write_text('secret\n')
    assert token_available()
    monkeypatch.delenv('RAY_AUTH_TOKEN_PATH')
    monkeypatch.setenv('RAY_AUTH_TOKEN', 'secret')
    assert token_available()
