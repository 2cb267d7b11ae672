"""The sim node with a chosen world, as ``ros2 run nav_sim sim_node -p world:=...`` starts it."""

from __future__ import annotations

import json
import subprocess

import pytest

from helpers import interrupt
from nav_sim.paths import executable_path
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import ros_args

EXECUTABLE = executable_path('nav_sim', 'sim_node')


def start(namespace: str, **params: object) -> subprocess.Popen:
    return subprocess.Popen([str(EXECUTABLE), *ros_args(namespace, params)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finished(process: subprocess.Popen) -> tuple[int, str, str]:
    try:
        out, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            interrupt(process)
    return process.returncode, out, err


@pytest.mark.parametrize(('world', 'expected'), [
    ('{tmp}/missing.xml', ['world file {tmp}/missing.xml not found: give an existing MJCF file, '
                           'or the name of a shipped world (arena.xml, clutter.xml, rooms.xml)']),
    ('{tmp}/broken.xml', ['{tmp}/broken.xml:3:2: malformed XML: mismatched tag']),
    ('{tmp}/no_robot.xml', ["{tmp}/no_robot.xml: missing body 'robot': the robot base: a body of "
                            'the worldbody, not mocap (docs/worlds.md)']),
], ids=['missing', 'malformed', 'no-robot'])
def test_a_bad_world_is_one_line_per_problem_and_exit_code_2(tmp_path, namespace, world,
                                                              expected):
    (tmp_path / 'broken.xml').write_text('<mujoco>\n<worldbody>\n</mujoco>\n')
    (tmp_path / 'no_robot.xml').write_text(
        '<mujoco><worldbody><geom name="floor" type="plane" size="1 1 .1"/></worldbody></mujoco>')
    code, out, err = finished(start(namespace, world=world.format(tmp=tmp_path)))
    assert code == 2, out + err
    assert 'Traceback' not in out + err
    lines = out.splitlines()
    assert lines[:1] == [f'sim_node: invalid world: {expected[0].format(tmp=tmp_path)}']
    assert all(line.startswith('sim_node: invalid world: ') and str(tmp_path) in line
               for line in lines)
    if world.endswith('no_robot.xml'):
        assert len(lines) == 14  # every required element but the floor, one line each


@pytest.mark.parametrize(('params', 'obstacles', 'look'), [
    ({'world': 'rooms.xml', 'randomize_look': True}, 4, True),  # the world's num_obstacles
    ({'world': 'rooms', 'num_obstacles': 2}, 2, False),         # the user's wins
])
def test_a_world_by_name_brings_its_settings_and_the_user_wins(namespace, params, obstacles,
                                                                look):
    process = start(namespace, **params)
    try:
        with SimClient(namespace, timeout=15.0) as client:
            client.wait_for_sim(60.0)
            _, scenario = client.reset(seed=101, split='heldout')
    finally:
        code, output = interrupt(process)
    assert code == 0 and 'Traceback' not in output, output
    assert len(scenario['obstacles']) == obstacles
    assert ('look' in scenario) is look
    assert 'share/nav_sim/worlds/rooms.xml' in output  # the ready line names the world file
    assert json.dumps(scenario)  # the reset's JSON, as clients and traces keep it
