"""The env in every shipped world, the world's settings in the env, and a bad world's errors.

The checklist passes in every shipped world; the world's settings reach the env and training;
a bad world is one clear line before any sim starts.
"""

from __future__ import annotations

import subprocess
import time

import pytest

from helpers import wait_until
from nav_gym.env.checks import run_checklist
from nav_gym.env.config import EnvConfig
from nav_gym.env.navigation import NavigationEnv
from nav_gym.training.config import TrainConfig, build
from nav_sim.errors import WorldError, WorldNotFoundError
from nav_sim.paths import executable_path
from nav_sim.ros.process import SimProcess


@pytest.mark.parametrize('sim_params', [
    {'world': 'clutter.xml'},
    {'world': 'rooms.xml'},
    {'world': 'rooms.xml', 'randomize_look': True},
    {'world': 'arena.xml', 'randomize_look': True},
], ids=['clutter', 'rooms', 'rooms-randomised', 'arena-randomised'])
def test_the_checklist_and_both_env_checkers_pass_in_the_world(namespace, sim_params):
    """arena.xml's checklist is test_commands' ``nav-gym-validate`` test."""
    config = EnvConfig(sim='embedded', namespace=namespace, sim_params=sim_params)
    env = NavigationEnv(config)
    try:
        checks = run_checklist(env, lambda **kw: NavigationEnv(config, **kw))
    finally:
        env.close()
    failed = [f'{c.name}: {c.measured}' for c in checks if not c.passed]
    assert not failed and len(checks) == 12, failed


def test_the_worlds_episode_limit_reaches_the_env_and_training_and_the_user_wins():
    assert EnvConfig().max_episode_steps == 100
    assert EnvConfig(sim_params={'world': 'rooms.xml'}).max_episode_steps == 200
    assert EnvConfig(sim_params={'world': 'clutter'}, max_episode_steps=7).max_episode_steps == 7
    config = build(None, {'sim_params': '{world: rooms.xml}'}).with_full_sim_params()
    assert (config.max_episode_steps, config.sim_params['num_obstacles'],
            config.sim_params['min_start_goal_distance']) == (200, 4, 1.0)
    assert config.env_config().max_episode_steps == 200
    mine = build(None, {'sim_params': '{world: rooms.xml, num_obstacles: 1}',
                        'max_episode_steps': '50'}).with_full_sim_params()
    assert (mine.max_episode_steps, mine.sim_params['num_obstacles']) == (50, 1)
    assert TrainConfig().max_episode_steps == 100  # arena.xml sets none


def test_an_env_refuses_a_bad_world_before_it_starts_a_sim(tmp_path):
    start = time.monotonic()
    with pytest.raises(WorldNotFoundError, match='missing.xml not found'):
        NavigationEnv(EnvConfig(sim='embedded', sim_params={'world': str(tmp_path /
                                                                         'missing.xml')}))
    (tmp_path / 'broken.xml').write_text('<mujoco><worldbody></mujoco>')
    with pytest.raises(WorldError, match=r'broken\.xml:1:\d+: malformed XML'):
        NavigationEnv(EnvConfig(sim='embedded', sim_params={'world': str(tmp_path /
                                                                         'broken.xml')}))
    assert time.monotonic() - start < 5.0  # no sim was started and waited for


def test_a_dead_sims_failure_is_its_own_error_line(namespace, tmp_path):
    process = SimProcess(namespace, {'world': str(tmp_path / 'missing.xml')})
    try:
        failure = wait_until(process.failure, 60.0, 'the sim exits')
    finally:
        process.stop()
    assert failure == (f'sim_node (pid {process.process.pid}) exited with code 2: invalid world: '
                       f'world file {tmp_path}/missing.xml not found: give an existing MJCF '
                       'file, or the name of a shipped world (arena.xml, clutter.xml, '
                       'rooms.xml)')


def test_validate_names_each_violation_of_a_world_in_one_line(tmp_path):
    world = tmp_path / 'no_robot.xml'
    world.write_text('<mujoco><worldbody><geom name="floor" type="plane" size="1 1 .1"/>'
                     '</worldbody></mujoco>')
    validate = executable_path('nav_gym', 'validate')
    result = subprocess.run([str(validate), '--sim', 'embedded', '--sim-params',
                             f'{{world: {world}}}'], capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert 'Traceback' not in result.stdout + result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 14 and all(
        line.startswith(f'nav-gym-validate: error: {world}: missing ') for line in lines), lines
