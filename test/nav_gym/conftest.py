from __future__ import annotations

from collections.abc import Iterator

import pytest

from nav_gym.env.navigation import NavigationEnv


@pytest.fixture(scope='module')
def env() -> Iterator[NavigationEnv]:
    """One embedded sim + env per test module (starting a sim costs about a second)."""
    environment = NavigationEnv(sim='embedded')
    yield environment
    environment.close()
