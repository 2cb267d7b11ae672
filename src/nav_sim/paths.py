"""Locate installed resources through the ament index, the way ROS 2 tools do."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

from nav_sim.errors import WorldNotFoundError

PACKAGE = 'nav_sim'
#: the characters of a name that becomes one path component (a run's, a sweep's, a sweep's
#: configuration and trial names, which hold ``KEY=VALUE``)
NAME_CHARACTERS = 'A-Za-z0-9_=.-'
#: a user-given name that becomes one path component: no separator, no leading '.' or '-'
PLAIN_NAME = re.compile(rf'[A-Za-z0-9_=][{NAME_CHARACTERS}]{{0,127}}')


def plain_name_problem(what: str, name: str) -> str | None:
    """Say why ``name`` cannot be one plain path component (None if it can).

    Run and sweep names become directories under ``--runs-dir`` or the sweep storage: a name
    with a separator, ``..`` or a leading dot would land elsewhere or hide.  Paths a user gives
    as paths (``--runs-dir``, ``--out``) are not names.
    """
    if PLAIN_NAME.fullmatch(name):
        return None
    return (f"{what} must be one plain path component: 1 to 128 letters, digits, '_', '=', "
            f"'.' or '-', not starting with '.' or '-', got {name!r}")


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


def executable_path(package: str, executable: str) -> Path | None:
    """``<prefix>/lib/<package>/<executable>``, where ``ros2 run`` looks, or None if unregistered.

    The path is returned whether or not the file exists there.
    """
    prefix = package_prefix(package)
    return None if prefix is None else prefix / 'lib' / package / executable


def find_world(world: str) -> Path:
    """Resolve a world file: an existing path, or a name under ``share/nav_sim/worlds``.

    A name may leave out its ``.xml`` (``rooms`` is ``rooms.xml``).
    """
    candidate = Path(world).expanduser()
    if candidate.is_file():
        return candidate.resolve()
    share = share_directory()
    shipped = sorted(p.name for p in (share / 'worlds').glob('*.xml')) if share else []
    if candidate.name != world or not world:  # a path: nothing to look up by name
        raise WorldNotFoundError(f'world file {candidate} not found: give an existing MJCF '
                                 f'file, or the name of a shipped world ({", ".join(shipped)})')
    searched: list[str] = [str(candidate)]
    if share is not None:
        names = [world] if candidate.suffix else [world, f'{world}.xml']
        for name in names:
            path = share / 'worlds' / name
            if path.is_file():
                return path
            searched.append(str(path))
        raise WorldNotFoundError(f'world {world!r} not found; searched: {", ".join(searched)}. '
                                 f'The shipped worlds are {", ".join(shipped)}; a world of '
                                 'your own is given by its path (docs/worlds.md)')
    searched.extend(f'{p}/share/ament_index/resource_index/packages/{PACKAGE}'
                    for p in ament_prefixes())
    raise WorldNotFoundError(
        f'world {world!r} not found; searched: {", ".join(searched)}. Install the project '
        f'(pip install .) or set AMENT_PREFIX_PATH to the prefix it was installed into.')
