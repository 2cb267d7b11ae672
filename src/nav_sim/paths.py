"""Locate installed resources through the ament index, the way ROS 2 tools do."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from nav_sim.errors import WorldNotFoundError

PACKAGE = 'nav_sim'


def ament_prefixes() -> list[Path]:
    """Prefixes to search: AMENT_PREFIX_PATH, then this interpreter's prefix (the venv)."""
    prefixes = [Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    prefixes.append(Path(sys.prefix))
    unique: list[Path] = []
    for prefix in prefixes:
        if prefix not in unique:
            unique.append(prefix)
    return unique


def package_prefix(package: str) -> Path | None:
    """Return the first prefix whose ament index registers ``package``, or None.

    This is the lookup ``get_package_prefix`` does.
    """
    for prefix in ament_prefixes():
        if (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / package).is_file():
            return prefix
    return None


def share_directory(package: str = PACKAGE) -> Path | None:
    """``<prefix>/share/<package>`` of the registered package, or None."""
    prefix = package_prefix(package)
    return None if prefix is None else prefix / 'share' / package


def find_world(world: str) -> Path:
    """Resolve a world file: an existing path, or a name under ``share/nav_sim/worlds``."""
    candidate = Path(world).expanduser()
    if candidate.is_file():
        return candidate.resolve()
    searched: list[str] = [str(candidate)]
    share = share_directory()
    if share is not None:
        path = share / 'worlds' / world
        if path.is_file():
            return path
        searched.append(str(path))
    else:
        searched.extend(f'{p}/share/ament_index/resource_index/packages/{PACKAGE}'
                        for p in ament_prefixes())
    raise WorldNotFoundError(
        f'world {world!r} not found; searched: {", ".join(searched)}. Install the project '
        f'(pip install .) or set AMENT_PREFIX_PATH to the prefix it was installed into.')
