"""The one wait of the tests: its value, its failure message, its sleeps."""

from __future__ import annotations

import time

import pytest

import helpers
from helpers import wait_until


def test_wait_until_returns_the_first_truthy_value():
    values = iter([0, None, '', 'ready', 'later'])
    assert wait_until(lambda: next(values), 5.0, 'a value', interval=0) == 'ready'


def test_wait_until_fails_naming_what_it_waited_for():
    with pytest.raises(pytest.fail.Exception,
                       match=r'^the thing: not within 0.05 s\nonly this came$'):
        wait_until(lambda: False, 0.05, 'the thing', details=lambda: 'only this came')


def test_wait_until_checks_at_the_deadline_and_never_sleeps_past_it(monkeypatch):
    sleeps, real_sleep = [], time.sleep
    monkeypatch.setattr(helpers.time, 'sleep', lambda s: (sleeps.append(s), real_sleep(s)))
    calls = []
    start = time.monotonic()
    with pytest.raises(pytest.fail.Exception, match='nothing: not within 0.1 s'):
        wait_until(lambda: calls.append(time.monotonic()), 0.1, 'nothing', interval=0.04)
    assert sleeps and all(0 < s <= 0.04 for s in sleeps)
    assert calls[-1] - start >= 0.1  # one last look once the time is up
