from __future__ import annotations

from collections.abc import Iterator

import pytest

from nav_sim.core.config import SimConfig
from nav_sim.core.sim import NavSim


@pytest.fixture(scope='module')
def sim() -> Iterator[NavSim]:
    core = NavSim(SimConfig())
    yield core
    core.close()

