"""Every setting's range, checked when the configuration is read, and names that become paths.

A bad value is refused before any sim, directory or file exists, in one line naming the key,
the value and what is allowed.

The cases are generated from the settings' declarations (``Bounds`` in each field's metadata):
a value just outside every bound of every training, env, learner and sim setting, through the
command line, a config file and a sweep's ``--set``.
"""

from __future__ import annotations

import dataclasses
import math
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from helpers import reported_as_another_error
from nav_eval import sweep
from nav_gym import train
from nav_gym.cli import run_command
from nav_gym.training.config import TrainConfig
from nav_sim.core.config import Bounds, SimConfig
from nav_sim.errors import ConfigError
from nav_sim.ros.settings import NodeConfig, check_sim_params

TRAIN = str(Path(sys.prefix) / 'bin' / 'nav-gym-train')
SWEEP = str(Path(sys.prefix) / 'bin' / 'visnav-sweep')


def cases(config: type) -> list[tuple[str, object, Bounds]]:
    """Every bounded field of ``config`` with each value just outside its bounds."""
    out = []
    for item in dataclasses.fields(config):
        bounds = item.metadata.get('bounds')
        if bounds is not None:
            out += [(item.name, value, bounds) for value in bounds.outside(type(item.default))]
    return out


TRAIN_CASES = cases(TrainConfig)
SIM_CASES = cases(SimConfig)


def text(value: object) -> str:
    return 'nan' if isinstance(value, float) and math.isnan(value) else \
        ('inf' if value == math.inf else str(value))


def test_the_cases_cover_every_kind_of_setting():
    names = {name for name, _, _ in TRAIN_CASES}
    assert {'learning_rate', 'gamma', 'exploration_final_eps', 'batch_size', 'n_steps',
            'priority_alpha', 'forward_speed', 'sim_timeout', 'max_episode_steps'} <= names
    assert len(TRAIN_CASES) >= 60 and len(SIM_CASES) >= 50


@pytest.fixture
def restore_sigterm():
    handler = signal.getsignal(signal.SIGTERM)
    yield
    signal.signal(signal.SIGTERM, handler)


def one_line_error(capsys, main, argv: list[str]) -> str:
    with pytest.raises(SystemExit) as exited:
        main(argv)
    assert exited.value.code not in (0, None)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_every_training_setting_from_the_command_line_and_a_config_file(
        tmp_path, capsys, restore_sigterm):
    runs = tmp_path / 'runs'
    for name, value, bounds in TRAIN_CASES:
        flag = '--' + name.replace('_', '-')
        line = one_line_error(capsys, train.main, ['--runs-dir', str(runs), flag, text(value)])
        assert f'{name} must be {bounds.describe()}, got' in line, line
        config = tmp_path / f'{name}.yaml'
        config.write_text(yaml.safe_dump({name: value}))
        line = one_line_error(capsys, train.main,
                              ['--runs-dir', str(runs), '--config', str(config)])
        assert f'{name} must be {bounds.describe()}, got' in line, line
    assert not runs.exists()  # nothing started: no run directory


def test_every_sim_setting_in_sim_params(tmp_path, capsys, restore_sigterm):
    runs = tmp_path / 'runs'
    for name, value, bounds in SIM_CASES:
        line = one_line_error(capsys, train.main, ['--runs-dir', str(runs), '--sim-params',
                                                   f'{{"{name}": {text(value)}}}'])
        assert f'sim_params: {name} must be {bounds.describe()}, got' in line, line
    assert not runs.exists()


def test_every_setting_in_a_sweeps_set(tmp_path, capsys):
    storage = tmp_path / 'sweeps'
    for name, value, bounds in TRAIN_CASES + SIM_CASES:
        if name == 'seed':  # the sweep's axis: --seeds
            continue
        line = one_line_error(capsys, sweep.main, ['--storage', str(storage), '--name', 'x',
                                                   '--set', f'{name}={text(value)}'])
        assert f'{name} must be {bounds.describe()}, got' in line, line
    line = one_line_error(capsys, sweep.main, ['--storage', str(storage), '--name', 'x', '--seeds',
                                               f'1,{2**32}'])
    assert line.endswith(f'training seed must be in [0, 4294967295], got {2**32}'), line
    assert not storage.exists()


def test_the_sim_nodes_own_settings_and_a_params_file(tmp_path):
    for name, value, _ in cases(NodeConfig) + SIM_CASES:
        with pytest.raises(ConfigError, match=f'{name} must be '):
            check_sim_params({name: value})
    # the node itself, started as ros2 run starts it, with a params file
    from nav_sim.paths import executable_path
    params = tmp_path / 'sim.yaml'
    params.write_text('/**:\n  ros__parameters:\n    camera_pitch_deg: 95.0\n')
    result = subprocess.run([str(executable_path('nav_sim', 'sim_node')), '--ros-args',
                             '--params-file', str(params)], capture_output=True, text=True,
                            timeout=120)
    out = (result.stdout + result.stderr).strip()
    assert result.returncode == 2 and len(out.splitlines()) == 1, out
    assert 'camera_pitch_deg must be in [-89, 89], got 95.0' in out


def test_rules_between_settings_and_names():
    for values, message in [
        ({'buffer_size': 16, 'batch_size': 32}, 'buffer_size must be >= batch_size (32)'),
        ({'exploration_initial_eps': 0.1, 'exploration_final_eps': 0.2},
         'exploration_final_eps must be <= exploration_initial_eps'),
        ({'device': 'gpu'}, "device must be 'auto', 'cpu', 'cuda' or 'cuda:N'"),
        ({'run_name': 'a/b'}, 'run_name must be one plain path component'),
        ({'sim_params': {'bogus': 1}}, "unknown sim_node parameter(s) ['bogus']"),
        ({'namespace': 'robot 1'}, "namespace: 'robot 1' is not a ROS namespace"),
        ({'namespace': '/a//b'}, "namespace: '/a//b' is not a ROS namespace"),
        ({'namespace': '/1robot'}, "namespace: '/1robot' is not a ROS namespace"),
    ]:
        with pytest.raises(Exception, match=message.replace('(', r'\(').replace(')', r'\)')
                           .replace('[', r'\[').replace(']', r'\]')):
            TrainConfig(**values)


def test_a_namespace_is_taken_from_the_root_as_a_node_takes_it():
    from nav_sim.ros.process import node_ros_args

    # a relative namespace once reached the sim's `-r __ns:=robot1`, which rcl refuses
    assert [TrainConfig(namespace=ns).namespace for ns in ('', '/', 'robot1', '/robot1/',
                                                           'a/b_2')] == [
        '', '/', '/robot1', '/robot1', '/a/b_2']  # '/': the root, '': a fresh one for a sim
    assert TrainConfig(namespace='robot1').env_config().namespace == '/robot1'
    assert [env.namespace for env in TrainConfig(namespace='/', n_envs=2).env_configs()] == [
        '/env0', '/env1']  # was '//env0', which ROS refused
    assert node_ros_args('robot1') == ['--ros-args', '-r', '__ns:=/robot1']


def test_a_sim_client_names_its_namespace_by_the_same_rule():
    from nav_sim.ros.client import SimClient

    for given, named in (('robot1', '/robot1'), ('/robot1/', '/robot1'), ('/', '/'), ('', '')):
        client = SimClient(given, timeout=1.0)  # was 'robot1', and '/' became ''
        try:
            assert (client.namespace, client.node.get_namespace()) == (named, named or '/')
        finally:
            client.close()
    with pytest.raises(ValueError, match="'1robot' is not a ROS namespace"):
        SimClient('1robot')  # before any context or node is made


def test_a_name_under_a_namespace_is_joined_by_the_same_rule(tmp_path):
    from nav_eval.recording.recorder import BagRecorder
    from nav_sim.interface import full_name

    # the graph's node names, the envs' namespaces and the recorder once joined names each
    # their own way ('robot1' gave 'robot1/sim', and the recorder named the root '')
    assert [full_name(ns, 'sim') for ns in ('/robot1', 'robot1', '/robot1/', '/', '')] == [
        '/robot1/sim', '/robot1/sim', '/robot1/sim', '/sim', '/sim']
    assert [env.namespace for env in TrainConfig(namespace='lab', n_envs=2).env_configs()] == [
        '/lab/env0', '/lab/env1']
    for given, named in (('', '/'), ('/', '/'), ('robot1/', '/robot1')):
        recorder = BagRecorder(tmp_path / f'bag{len(named)}{len(given)}', given)
        try:
            assert recorder.namespace == named
        finally:
            recorder.close()


def test_a_bad_value_from_the_installed_command_is_one_line_and_nothing_is_written(tmp_path):
    result = subprocess.run([TRAIN, '--runs-dir', str(tmp_path / 'runs'), '--learning-rate',
                             '-1', '--total-timesteps', '300'], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode != 0
    assert result.stderr.strip() == ('nav-gym-train: error: command line: learning_rate must '
                                     'be > 0, got -1.0') or \
        result.stderr.strip() == 'nav-gym-train: error: learning_rate must be > 0, got -1.0', \
        result.stderr
    assert not (tmp_path / 'runs').exists()


@pytest.mark.parametrize('name', ['../escape', '/abs', 'a/b', '..', '.hidden', 'x' * 200])
def test_names_that_become_paths_are_one_plain_component(tmp_path, name):
    runs = tmp_path / 'runs'
    runs.mkdir()
    result = subprocess.run([TRAIN, '--runs-dir', str(runs), '--run-name', name,
                             '--total-timesteps', '300'], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 1
    assert result.stderr.strip().startswith('nav-gym-train: error: run_name must be one plain '
                                            'path component'), result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert sorted(tmp_path.rglob('*')) == [runs]
    sweep_result = subprocess.run([SWEEP, '--storage', str(tmp_path / 's'), '--name', name],
                                  capture_output=True, text=True, timeout=120)
    assert sweep_result.returncode == 1
    assert 'error: --name must be one plain path component' in sweep_result.stderr
    assert not (tmp_path / 's').exists() and not (tmp_path / 'escape').exists()


def test_an_unexpected_error_is_one_line_and_the_traceback_is_there_on_request(
        capsys, monkeypatch):
    def broken() -> int:
        raise ZeroDivisionError('division by zero\nmore')
    with pytest.raises(SystemExit) as exited:
        run_command('nav-x', broken)
    assert exited.value.code == 1
    err = capsys.readouterr().err
    assert err.strip() == ('nav-x: error: unexpected ZeroDivisionError: division by zero (a '
                           'bug: please report it with the traceback that VISNAV_DEBUG=1 shows)')
    monkeypatch.setenv('VISNAV_DEBUG', '1')
    with pytest.raises(SystemExit):
        run_command('nav-x', broken)
    assert 'Traceback (most recent call last)' in capsys.readouterr().err


def test_a_ctrl_c_reported_as_another_error_exits_130(capsys):
    # a Ctrl-C that a C extension's call reported as SystemError (its cause the interrupt), as
    # rclpy's take_response did (2026-11-29): interrupted, not an unexpected error
    def body() -> int:
        raise reported_as_another_error()
    with pytest.raises(SystemExit) as exited:
        run_command('nav-x', body)
    assert exited.value.code == 130 and capsys.readouterr().err == 'nav-x: interrupted\n'
