"""Worlds in evaluation: maps and the live scene show walls and looks; a gone world, one line.

The report's maps and the live scene draw a world's interior walls and its drawn look; an
evaluation of a run whose world is gone is one line.
"""

from __future__ import annotations

import json
import subprocess

import matplotlib.pyplot as plt
import pytest
from matplotlib.colors import to_rgba

from nav_eval.evaluation.runner import arena_description
from nav_eval.reporting.plots import draw_arena
from nav_gym.training.config import TrainConfig
from nav_sim.core.config import SimConfig
from nav_sim.core.sim import NavSim
from nav_sim.paths import executable_path
from nav_sim.viz import topics as live_topics


@pytest.fixture(scope='module')
def rooms_scenario() -> dict:
    sim = NavSim(SimConfig.from_dict({'world': 'rooms.xml', 'randomize_look': True}))
    try:
        return sim.reset(201, 'heldout').to_dict()
    finally:
        sim.close()


def test_the_arena_description_has_the_interior_walls():
    assert arena_description({})['walls'] == []
    rooms = arena_description({'world': 'rooms.xml'})
    assert rooms['world'] == 'rooms.xml' and rooms['half_size'] == pytest.approx(1.2)
    assert len(rooms['walls']) == 6
    assert [0.0, 0.0, 0.025, 0.45] in [[round(v, 4) for v in w] for w in rooms['walls']]


def test_a_map_draws_the_walls_and_the_drawn_look(rooms_scenario):
    look = rooms_scenario['look']
    fig, ax = plt.subplots()
    try:
        draw_arena(ax, arena_description({'world': 'rooms.xml'}), rooms_scenario)
        walls = [p for p in ax.patches if p.get_gid() == 'wall']
        assert len(walls) == 6
        assert all(p.get_facecolor() == to_rgba(look['walls']) for p in walls)
        obstacles = [p for p in ax.patches if (p.get_gid() or '').startswith('obstacle_')]
        assert len(obstacles) == 4
        assert all(p.get_facecolor()[:3] == to_rgba(look['obstacles'])[:3] for p in obstacles)
        assert to_rgba(look['floor']) in [p.get_facecolor() for p in ax.patches]
    finally:
        plt.close(fig)


def test_the_live_scene_draws_the_drawn_look(rooms_scenario):
    arena = live_topics.arena_for({'world': 'rooms.xml'})
    markers = live_topics.scene_markers(arena, rooms_scenario, 0).markers
    colour = {m.ns: (m.color.r, m.color.g, m.color.b) for m in markers if m.ns}
    look = rooms_scenario['look']
    for ns, key in (('floor', 'floor'), ('walls', 'walls'), ('obstacles', 'obstacles')):
        assert colour[ns] == pytest.approx(look[key]), ns
    assert len([m for m in markers if m.ns == 'walls']) == 10  # 4 outer, 6 between rooms
    plain = live_topics.scene_markers(arena, {**rooms_scenario, 'look': None}, 0).markers
    assert {(m.color.r, m.color.g, m.color.b, m.color.a) for m in plain
            if m.ns == 'obstacles'} == {live_topics.OBSTACLE}


def test_evaluating_a_run_whose_world_is_gone_is_one_line(tmp_path):
    run = tmp_path / 'run'
    run.mkdir()
    gone = tmp_path / 'gone.xml'
    config = TrainConfig(max_episode_steps=15, sim_params={'world': 'clutter.xml'})
    # a run trained in a world that is gone since (a config checks its world when it is built)
    (run / 'config.yaml').write_text(config.to_yaml().replace('clutter.xml', str(gone)))
    evaluate = executable_path('nav_eval', 'evaluate')
    result = subprocess.run([str(evaluate), str(run), '--sets', 'random_train', '--no-record'],
                            capture_output=True, text=True, timeout=180)
    assert result.returncode == 1 and 'Traceback' not in result.stderr, result.stderr
    assert result.stderr.splitlines() == [
        f'nav-eval-evaluate: error: world file {gone} not found: give an existing MJCF file, or '
        'the name of a shipped world (arena.xml, clutter.xml, rooms.xml)']


def test_a_run_plays_in_another_world_with_that_worlds_settings():
    arena = TrainConfig().with_full_sim_params()
    rooms = arena.in_world({'world': 'rooms.xml'})
    assert (rooms.max_episode_steps, rooms.sim_params['num_obstacles'],
            rooms.sim_params['min_start_goal_distance']) == (200, 4, 1.0)
    back = rooms.in_world({'world': 'arena.xml'})
    assert back.sim_params == arena.sim_params and back.max_episode_steps == 100
    mine = arena.in_world({'world': 'clutter.xml', 'num_obstacles': 2, 'randomize_look': True})
    assert (mine.sim_params['num_obstacles'], mine.sim_params['obstacle_gap'],
            mine.sim_params['randomize_look'], mine.max_episode_steps) == (2, 0.1, True, 120)
    looks = arena.in_world({'randomize_look': True})  # the same world: only the look changes
    assert looks.max_episode_steps == 100
    assert {k: v for k, v in looks.sim_params.items() if k != 'randomize_look'} == {
        k: v for k, v in arena.sim_params.items() if k != 'randomize_look'}


def test_evaluate_plays_a_run_in_another_world_and_look_into_another_folder(tmp_path):
    from nav_eval.evaluation.runner import evaluate
    from nav_eval.evaluation.sets import plan_sets
    run = tmp_path / 'run'
    run.mkdir()
    (run / 'config.yaml').write_text(TrainConfig(max_episode_steps=15).with_full_sim_params()
                                     .to_yaml())
    out = tmp_path / 'rooms'
    sets = plan_sets(run, ['random_train'], (101, 102), (201,))
    results = evaluate(run, sets, out, record=False,
                       sim_params={'world': 'rooms.xml', 'randomize_look': True})
    assert results['config']['sim_params']['world'] == 'rooms.xml'
    assert results['config']['max_episode_steps'] == 200 and len(results['arena']['walls']) == 6
    trace = json.loads((out / 'traces' / 'random_train' / 'seed_101.json').read_text())
    assert len(trace['scenario']['obstacles']) == 4 and 'look' in trace['scenario']
    evaluate_command = executable_path('nav_eval', 'evaluate')
    refused = subprocess.run([str(evaluate_command), str(run), '--sets', 'random_train',
                              '--sim-params', '{world: rooms.xml}'], capture_output=True,
                             text=True, timeout=180)
    assert refused.returncode == 1 and 'write it with --out' in refused.stderr
    assert not (run / 'eval').exists()
