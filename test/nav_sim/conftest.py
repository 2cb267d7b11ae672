from __future__ import annotations

import itertools
import os
from collections.abc import Iterator

import pytest

from nav_sim.config import SimConfig
from nav_sim.sim import NavSim

_names = itertools.count()


@pytest.fixture(scope='module')
def sim() -> Iterator[NavSim]:
    core = NavSim(SimConfig())
    yield core
    core.close()


@pytest.fixture
def namespace() -> str:
    """Return a namespace no other test (or test run) uses."""
    return f'/t{os.getpid()}_{next(_names)}'
