"""Read a world file as text: well-formed XML, and the settings it carries (no MuJoCo).

A world may carry what it needs besides its geometry (more obstacles per layout, a longer
episode limit) as MuJoCo custom numerics named ``visnav:<setting>``::

    <custom>
      <numeric name="visnav:num_obstacles" data="8"/>
      <numeric name="visnav:max_episode_steps" data="150"/>
    </custom>

A setting is a sim parameter (``config/sim.yaml``) or one of ``ENV_SETTINGS``; it is the
default of a run in that world, and a value the user gives wins (docs/worlds.md).  The
settings are read from the world file itself (not from a file it includes), without compiling
it, so that a training configuration can follow its world cheaply.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from nav_sim.errors import WorldError
from nav_sim.paths import find_world

SETTING_PREFIX = 'visnav:'
#: settings a world may carry that are not sim parameters: the env's episode limit
ENV_SETTINGS = ('max_episode_steps',)


def parse_xml(path: Path) -> ET.Element:
    """Return the root element of a world file, or raise WorldError naming the line."""
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise WorldError(f'{path}: cannot read the world file ({exc.strerror})') from None
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        line, column = exc.position
        reason = str(exc).split(':')[0]
        raise WorldError(f'{path}:{line}:{column}: malformed XML: {reason}') from None
    if root.tag != 'mujoco':
        raise WorldError(f'{path}: not an MJCF world: the root element is <{root.tag}>, '
                         'not <mujoco> (docs/worlds.md has a minimal world)')
    return root


def world_settings(world: str) -> dict[str, float]:
    """Return the ``visnav:`` settings of a world (name or path) as numbers, by setting name.

    Raises WorldNotFoundError, or WorldError for malformed XML or a setting that is not one
    number.
    """
    path = find_world(world)
    settings: dict[str, float] = {}
    for numeric in parse_xml(path).iter('numeric'):
        name = numeric.get('name', '')
        if not name.startswith(SETTING_PREFIX):
            continue  # the world's own custom data
        values = (numeric.get('data') or '').split()
        try:
            (value,) = (float(v) for v in values)
        except ValueError:
            raise WorldError(f'{path}: <numeric name="{name}"> must hold one number as data, '
                             f'got {numeric.get("data")!r}') from None
        settings[name[len(SETTING_PREFIX):]] = value
    return settings
