from __future__ import annotations

import itertools
import os
from collections.abc import Iterator

import pytest

from nav_gym.env import NavigationEnv

_names = itertools.count()


@pytest.fixture
def namespace() -> str:
    return f'/g{os.getpid()}_{next(_names)}'


@pytest.fixture(scope='module')
def env() -> Iterator[NavigationEnv]:
    """One embedded sim + env per test module (starting a sim costs about a second)."""
    environment = NavigationEnv(sim='embedded')
    yield environment
    environment.close()
