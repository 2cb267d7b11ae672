"""Test-wide ROS isolation (a private DDS domain per test run, traffic kept on this machine).

Also the fixtures every test folder shares.  Plain helpers (``wait_until``, ``free_port``,
``interrupt``) are in ``helpers.py``: a conftest cannot be imported by name.
"""

from __future__ import annotations

import itertools
import os
import signal
import sys

import pytest

from nav_eval.sweeps.domain import DOMAIN_IDS, reserve_domain

# Must happen before rclpy is imported by any test module.  The domain is reserved the way a
# sweep's trials reserve theirs (a bound port per id, held until this run ends), so concurrent
# test runs and sweeps on this host never share one.
_DOMAIN = reserve_domain(DOMAIN_IDS)
os.environ['ROS_DOMAIN_ID'] = str(_DOMAIN.domain_id)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
os.environ.setdefault('MUJOCO_GL', 'egl')
# a child that crashes (SIGSEGV, SIGABRT) prints its Python stack into the output a test reports
os.environ.setdefault('PYTHONFAULTHANDLER', '1')
# The tests press Ctrl-C on commands as a terminal does.  Started as a background job of a
# non-interactive shell (`nohup make test &`), this process inherits an ignored SIGINT and so
# would every command it starts: a trainer started so ignores Ctrl-C (Python installs no
# KeyboardInterrupt handler), which is right for it and wrong for these tests.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

_names = itertools.count()


@pytest.fixture
def namespace() -> str:
    """Return a ROS namespace no other test, in this run or a concurrent one, uses.

    The process id keeps concurrent runs apart; the counter keeps this run's tests apart.
    """
    return f'/t{os.getpid()}_{next(_names)}'


@pytest.fixture(scope='session')
def spaces_only() -> type:
    """Return an env class with only the spaces of visnav/Navigation-v0 (a model, no sim)."""
    import gymnasium as gym
    import numpy as np

    class SpacesOnly(gym.Env):
        observation_space = gym.spaces.Box(0, 255, (3, 84, 84), np.uint8)
        action_space = gym.spaces.Discrete(3)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            return self.observation_space.sample(), {}

        def step(self, action):
            return self.observation_space.sample(), 0.0, False, False, {}

    return SpacesOnly
