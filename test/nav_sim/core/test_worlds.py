"""Worlds: the contract checked at load, the shipped worlds, their settings and solvable banks.

Pure tests (no ROS): worlds are written to ``tmp_path`` from docs/worlds.md's minimal example,
each broken in one way.
"""

from __future__ import annotations

import hashlib
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from nav_sim.core.config import SimConfig
from nav_sim.core.contract import REQUIRED
from nav_sim.core.footprint import FootprintMap
from nav_sim.core.geometry import ArenaGeometry, Layout, ObstacleShape, Placement, clearance
from nav_sim.core.scenarios import build_banks, sample_scenario
from nav_sim.core.sim import NavSim
from nav_sim.core.world import load_arena
from nav_sim.errors import WorldError, WorldNotFoundError
from nav_sim.paths import find_world

DOCS = REPO / 'docs' / 'worlds.md'
WORLDS = ('arena.xml', 'clutter.xml', 'rooms.xml')


def example() -> str:
    """Return the minimal world of docs/worlds.md (its one ``xml`` block)."""
    (block,) = re.findall(r'```xml\n(<mujoco.*?)```', DOCS.read_text(), re.S)
    return block


def write(tmp_path: Path, text: str, name: str = 'world.xml') -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def edited(tmp_path: Path, change) -> str:
    """Write the example with ``change(root)`` applied to its parsed XML; return the path."""
    root = ET.fromstring(example())
    change(root)
    return write(tmp_path, ET.tostring(root, encoding='unicode'))


def named(root: ET.Element, tag: str, name: str) -> ET.Element:
    return next(e for e in root.iter(tag) if e.get('name') == name)


def problems(world: str, **params) -> list[str]:
    with pytest.raises(WorldError) as info:
        load_arena({'world': world, **params})
    return str(info.value).splitlines()


# --- the contract ---------------------------------------------------------------------------
def test_the_docs_example_is_a_valid_world_that_plays(tmp_path):
    sim = NavSim(SimConfig.from_dict({'world': write(tmp_path, example())}))
    try:
        scenario = sim.reset(101, 'train')
        assert len(scenario.layout.placements) == 1  # its own setting: num_obstacles 1
        assert sim.render().std() > 0
    finally:
        sim.close()


def test_the_docs_table_lists_exactly_the_required_elements():
    rows = re.findall(r'^\| (\w+) \| `(\w+)` \| (.+) \|$', DOCS.read_text(), re.M)
    assert [(kind, name, rule) for kind, name, rule in rows] == [
        (e.kind, e.name, e.rule) for e in REQUIRED]


@pytest.mark.parametrize('element', REQUIRED, ids=lambda e: f'{e.kind}-{e.name}')
def test_each_required_element_removed_is_one_line_naming_it(tmp_path, element):
    def remove(root: ET.Element) -> None:
        for parent in root.iter():
            for child in list(parent):
                if child.tag == element.kind and child.get('name') == element.name:
                    parent.remove(child)
    path = edited(tmp_path, remove)
    lines = problems(path)
    assert f"{path}: missing {element.kind} '{element.name}': {element.rule}" in '\n'.join(lines)
    assert all(line.startswith(f'{path}: ') for line in lines)


def camera_on_the_goal(root: ET.Element) -> None:
    robot = named(root, 'body', 'robot')
    camera = robot.find('camera')
    robot.remove(camera)
    named(root, 'body', 'goal').append(camera)


@pytest.mark.parametrize(('change', 'expected'), [
    (camera_on_the_goal, "camera 'front_camera' is on body 'goal', not on body 'robot'"),
    (lambda r: named(r, 'geom', 'floor').attrib.update(contype='1', conaffinity='1'),
     "geom 'floor' must collide with nothing"),
    (lambda r: named(r, 'geom', 'robot_body').set('type', 'sphere'),
     "geom 'robot_body' is a sphere, not a cylinder"),
    (lambda r: named(r, 'joint', 'base_yaw').set('type', 'slide'),
     "joint 'base_yaw' is a slide joint"),
    (lambda r: named(r, 'geom', 'wall_north').set('euler', '0 0 30'),
     "wall 'wall_north' must be axis-aligned"),
    (lambda r: named(r, 'geom', 'wall_west').set('pos', '-1.2 0 0.075'),
     'the outer walls must enclose a square centred at the origin'),
    (lambda r: r.find('worldbody').append(ET.fromstring(
        '<geom name="rock" type="sphere" pos="0.3 0.3 0.05" size="0.05"/>')),
     "geom 'rock' collides with the robot but is neither a wall_* box nor an obstacle slot"),
    (lambda r: named(r, 'body', 'goal').attrib.pop('mocap'), "body 'goal' must be mocap"),
    (lambda r: named(r, 'geom', 'goal').set('rgba', '0.8 0.2 0.2 1'),
     "geom 'goal' must be green"),
    (lambda r: named(r, 'geom', 'obstacle_0').set('rgba', '0.2 0.7 0.3 1'),
     "geom 'obstacle_0' takes the goal's hues"),
], ids=['camera-off-the-robot', 'colliding-floor', 'round-robot', 'sliding-yaw',
        'rotated-wall', 'open-square', 'unknown-collider', 'fixed-goal', 'red-goal',
        'green-obstacle'])
def test_a_wrong_element_is_one_line_naming_it(tmp_path, change, expected):
    path = edited(tmp_path, change)
    lines = problems(path)
    assert any(line.startswith(f'{path}: {expected}') for line in lines), lines


def test_too_few_slots_for_num_obstacles(tmp_path):
    path = write(tmp_path, example())
    assert problems(path, num_obstacles=2) == [
        f'{path}: 1 obstacle slots (obstacle_0..0), but num_obstacles is 2: add slots or lower '
        'num_obstacles']


def test_an_arena_too_small_for_any_scenario(tmp_path):
    small = example().replace('1.025', '0.325').replace('1.05 ', '0.35 ').replace(' 1.05', ' 0.35')
    path = write(tmp_path, small)
    (line,) = problems(path)
    assert line.startswith(f'{path}: the arena (0.60 m wide) is too small for any scenario')


def test_malformed_xml_names_the_line(tmp_path):
    text = example().replace('</body>', '</bod>', 1)
    line = text[:text.index('</bod>')].count('\n') + 1
    (problem,) = problems(write(tmp_path, text))
    assert re.fullmatch(rf'.*world\.xml:{line}:\d+: malformed XML: mismatched tag', problem)


def test_xml_mujoco_refuses_names_the_element_and_line(tmp_path):
    (problem,) = problems(write(tmp_path, example().replace('<light ', '<light bogus="1" ')))
    assert 'MuJoCo cannot load it' in problem and 'bogus' in problem and 'line' in problem


def test_a_valid_mujoco_model_without_our_robot_lists_what_is_missing(tmp_path):
    path = write(tmp_path, '<mujoco><worldbody><geom name="floor" type="plane" size="1 1 .1"/>'
                 '</worldbody></mujoco>')
    lines = problems(path)
    assert len(lines) == len(REQUIRED) - 1  # everything but the floor
    assert lines[0] == (f"{path}: missing body 'robot': the robot base: a body of the worldbody, "
                        'not mocap (docs/worlds.md)')


def test_a_missing_world_says_what_exists(tmp_path):
    with pytest.raises(WorldNotFoundError, match='arena.xml, clutter.xml, rooms.xml'):
        load_arena({'world': str(tmp_path / 'missing.xml')})
    with pytest.raises(WorldNotFoundError, match='searched'):
        find_world('no_such_world')


# --- the shipped worlds and their settings --------------------------------------------------
@pytest.mark.parametrize('world', WORLDS)
def test_shipped_worlds_are_found_by_name_with_or_without_xml(world):
    assert find_world(world) == find_world(world.removesuffix('.xml'))
    assert find_world(world).parent.name == 'worlds'


def test_a_world_sets_its_defaults_and_the_user_wins():
    assert SimConfig.from_dict({'world': 'clutter.xml'}).num_obstacles == 8
    assert SimConfig.from_dict({'world': 'rooms'}).min_start_goal_distance == 1.0
    assert SimConfig.from_dict({'world': 'rooms.xml', 'num_obstacles': 1}).num_obstacles == 1
    assert SimConfig.from_dict({}) == SimConfig()  # arena.xml sets nothing


def test_a_world_setting_must_be_known_and_well_typed(tmp_path):
    def setting(name: str, value: str) -> str:
        return write(tmp_path, example().replace(
            '<numeric name="visnav:num_obstacles" data="1"/>',
            f'<numeric name="visnav:{name}" data="{value}"/>'), f'{name}.xml')
    with pytest.raises(WorldError, match='unknown setting "visnav:num_obstacle"'):
        SimConfig.from_dict({'world': setting('num_obstacle', '1')})
    with pytest.raises(WorldError, match='num_obstacles takes an integer, got 1.5'):
        SimConfig.from_dict({'world': setting('num_obstacles', '1.5')})
    with pytest.raises(WorldError, match='must hold one number'):
        SimConfig.from_dict({'world': setting('num_obstacles', '1 2')})


# --- banks and solvability ------------------------------------------------------------------
def scenario_digest(seeds: range, split: str, banks, geometry, config) -> str:
    digest = hashlib.sha256()
    for seed in seeds:
        s = sample_scenario(seed, split, banks, geometry, config)
        values = [*s.start, *s.goal, s.initial_distance]
        for p in s.layout.placements:
            values += [p.slot, p.x, p.y, p.yaw]
        digest.update(repr([s.layout.index] + [float(v).hex() for v in values]).encode())
    return digest.hexdigest()


def test_arena_scenarios_are_bit_identical_to_before_worlds_existed():
    """Seeds 101-600 / 201-700 of arena.xml: the digests of the code before this change."""
    geometry, config = load_arena({})
    banks = build_banks(config, geometry)
    assert scenario_digest(range(101, 601), 'train', banks, geometry, config) == (
        'e3317c8b028867391ffd086278b42c1a2e414042eda783f8c87de30d50d8696e')
    assert scenario_digest(range(201, 701), 'heldout', banks, geometry, config) == (
        'c53ceb835c1815b3e03f751ac748ca76f0f10f97db167429abe2d451aade3639')


@pytest.mark.parametrize('world', WORLDS)
def test_every_layout_of_every_bank_plays_solvable_scenarios(world):
    """The oracle's distance field (Dijkstra) is finite at the start of two scenarios a layout."""
    geometry, config = load_arena({'world': world})
    banks = build_banks(config, geometry)
    field_map = FootprintMap(geometry, config)
    for split, first in (('train', 101), ('heldout', 201)):
        counts = dict.fromkeys((layout.index for layout in banks[split]), 0)
        seed = first
        while min(counts.values()) < 2 and seed < first + 400:
            s = sample_scenario(seed, split, banks, geometry, config)
            if counts[s.layout.index] < 2:
                counts[s.layout.index] += 1
                distance = field_map.field(s.layout, s.goal).at(*s.start[:2])
                assert math.isfinite(distance), (world, split, seed)
                # geodesic to the goal's 10 cm region: never shorter than the straight line
                assert distance >= s.initial_distance - config.goal_radius - 0.02
            seed += 1
        assert min(counts.values()) == 2, (world, split, counts)


def test_the_generator_draws_again_until_a_path_exists():
    """A wall splits the arena in two: every scenario keeps start and goal on one side."""
    wall = (0.0, 0.0, 0.1, 0.025, 1.0, 0.1)  # x = 0, floor to ceiling of the square
    geometry = ArenaGeometry(1.0, 0.037, (ObstacleShape('obstacle_0', 'box', 0.05, 0.05),),
                             (wall,))
    config = SimConfig(num_obstacles=1)
    banks = build_banks(config, geometry)
    plain = ArenaGeometry(1.0, 0.037, geometry.shapes)
    redrawn = 0
    for seed in range(40):
        s = sample_scenario(seed, 'train', banks, geometry, config)
        assert (s.start[0] > 0) == (s.goal[0] > 0), seed
        assert clearance(*s.start[:2], s.layout, geometry) > 0.037
        first = sample_scenario(seed, 'train', banks, plain, config)  # no wall: first draws
        redrawn += (first.start, first.goal) != (s.start, s.goal)
    assert redrawn > 5  # some first draws crossed the wall and were drawn again


def test_reachable_is_the_fields_answer_and_free_cells_the_scalar_clearance():
    geometry, config = load_arena({'world': 'rooms.xml'})
    banks = build_banks(config, geometry)
    footprint = FootprintMap(geometry, config)
    layout = banks['train'][0]
    free = footprint.free_cells(layout)
    scalar = np.array([[clearance(x, y, layout, geometry) >= footprint.footprint
                        for x in footprint.centres] for y in footprint.centres])
    assert np.array_equal(free, scalar)
    closed = Layout('train', -1, (Placement(1, -0.6, 0.0, 0.0),))  # a box in a doorway
    rng = np.random.default_rng(0)
    for check in (layout, closed):
        goal = (0.6, 0.6)
        field = footprint.field(check, goal)
        for x, y in rng.uniform(-1.2, 1.2, size=(200, 2)):
            assert footprint.reachable(check, (x, y), goal) == math.isfinite(field.at(x, y))


@pytest.mark.parametrize('randomize_look', [False, True], ids=['plain', 'drawn-looks'])
@pytest.mark.parametrize('world', WORLDS)
def test_every_world_gives_the_same_bytes_for_the_same_seed(world, randomize_look):
    def frames(sim: NavSim) -> list[bytes]:
        out = []
        for seed, split in ((101, 'train'), (102, 'train'), (201, 'heldout')):
            sim.reset(seed, split)
            out.append(sim.render().tobytes())
        return out
    config = SimConfig.from_dict({'world': world, 'randomize_look': randomize_look})
    first, second = NavSim(config), NavSim(config)
    try:
        images = frames(first)
        assert images == frames(second) and len(set(images)) == 3
    finally:
        first.close()
        second.close()
