"""The validation, scripted-episode and training commands, run as ``ros2 run`` would."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import REPO, wait_until
from nav_gym.errors import CheckpointError, TrainConfigError
from nav_gym.training.checkpoints import load_model
from nav_gym.training.config import TrainConfig, build, load_yaml
from nav_gym.training.trainer import checkpoints
from nav_sim.core.config import SimConfig
from nav_sim.paths import executable_path

SMOKE = ['--total-timesteps', '300', '--learning-starts', '100', '--checkpoint-freq', '150',
         '--buffer-size', '1000', '--sim', 'embedded']


def ros2_run(package: str, executable: str) -> str:
    return str(executable_path(package, executable))


def run(args: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(args, capture_output=True, text=True, timeout=timeout)


def monitor_rows(path: Path) -> list[str]:
    """Return the episode rows of a Monitor CSV written so far (none before it exists)."""
    if not path.is_file():
        return []
    lines = path.read_text().splitlines()
    return [line for line in lines[2:] if line.strip()]


def leftover_sims(marker: str) -> list[str]:
    out = subprocess.run(['pgrep', '-af', marker], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if 'pgrep' not in line]


def test_validate_prints_a_passing_checklist(tmp_path):
    result = run([ros2_run('nav_gym', 'validate'), '--sim', 'embedded', '--json',
                  str(tmp_path / 'checks.json')])
    assert result.returncode == 0, result.stdout + result.stderr
    for name in ('Observation shape', 'Observation dtype', 'Observation range', 'Action space',
                 'Reset reproducibility', 'Goal detection', 'Collision detection', 'Timeout',
                 'Motor stop', 'check_env() (SB3)', 'check_env() (Gymnasium)'):
        assert f'PASS  {name}' in result.stdout
    assert '12 passed, 0 failed' in result.stdout
    checks = json.loads((tmp_path / 'checks.json').read_text())
    assert all(c['passed'] for c in checks) and len(checks) == 12


def test_validate_fails_visibly_without_a_sim():
    result = run([ros2_run('nav_gym', 'validate'), '--sim', 'attach', '--namespace',
                  '/nobody_here', '--sim-timeout', '1'])
    assert result.returncode == 1
    assert 'ros2 run nav_sim sim_node' in result.stderr and 'Traceback' not in result.stderr


def test_scripted_episode_prints_each_transition_and_stops():
    result = run([ros2_run('nav_gym', 'episode'), '--seed', '101', '--sim', 'embedded'])
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert 'initial distance:' in out and 'scenario: seed 101' in out
    assert '1 forward' in out and '0 left' in out and '2 right' in out
    assert 'robot stopped' in out


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')  # SB3's own, on any n-step load
def test_smoke_training_checkpoints_resumes_and_loads(tmp_path):
    import numpy as np
    result = run([ros2_run('nav_gym', 'train'), *SMOKE, '--runs-dir', str(tmp_path),
                  '--run-name', 'smoke', '--keep-replay-buffer', 'true'])
    assert result.returncode == 0, result.stdout + result.stderr
    run_dir = tmp_path / 'smoke'
    assert [s for s, _ in checkpoints(run_dir)] == [0, 150, 300]
    for name in ('config.yaml', 'monitor.csv', 'final_model.zip', 'summary.json'):
        assert (run_dir / name).is_file()
    assert (run_dir / 'monitor.csv').read_text().startswith('#{')
    assert any((run_dir / 'tb').rglob('events.out.tfevents.*'))
    summary = json.loads((run_dir / 'summary.json').read_text())
    assert summary['num_timesteps'] == 300 and 0 < summary['env_share'] < 1
    assert summary['config']['learning_rate'] == 1e-4 and summary['config']['seed'] == 9
    # kept on request (--keep-replay-buffer), tied to the last checkpoint
    assert (run_dir / 'checkpoints' / 'replay_buffer.step').read_text() == '300'
    # the run keeps every sim parameter it was trained with, not just the overridden ones
    saved = load_yaml(run_dir / 'config.yaml')['sim_params']
    assert saved == dataclasses.asdict(SimConfig())
    # the learner's OpenMP threads wait passively (nav_gym.training.timing) unless the user chose
    assert summary['omp_wait_policy'] == os.environ.get('OMP_WAIT_POLICY', 'PASSIVE')
    # the time budget of a step (issue 12): the env's phases, the learner's share, the sim's
    budget = summary['time_budget']
    assert budget['env_step']['steps'] >= 290
    for phase in ('transport_ms', 'image_ms', 'gradient_step_ms', 'predict_ms', 'step_ms'):
        assert budget['env_step'][phase] > 0, phase
    assert budget['env_step']['live_ms'] == 0.0  # no --live

    result = run([ros2_run('nav_gym', 'train'), '--resume', str(run_dir),
                  '--total-timesteps', '450'])
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'from dqn_300_steps.zip (step 300) with its replay buffer' in result.stdout
    assert '150 steps remain' in result.stdout
    steps = [s for s, _ in checkpoints(run_dir)]
    # SB3 collects train_freq (4) steps per rollout, so a run can end a few steps past its total
    assert 450 in steps and 450 <= steps[-1] < 454

    from stable_baselines3 import DQN
    model = DQN.load(run_dir / 'final_model.zip', device='cpu')
    assert model.num_timesteps == steps[-1]
    action, _ = model.predict(np.zeros(model.observation_space.shape, np.uint8),
                              deterministic=True)  # the default learner's stack
    assert int(action) in (0, 1, 2)

    corrupt = checkpoints(run_dir)[-1][1]
    corrupt.write_bytes(b'not a zip file')
    result = run([ros2_run('nav_gym', 'train'), '--resume', str(run_dir)])
    assert result.returncode == 1
    assert 'corrupt or incompatible' in result.stderr and 'Traceback' not in result.stderr
    with pytest.raises(CheckpointError, match=corrupt.name):
        load_model(corrupt, None, 'cpu')


def test_ctrl_c_saves_a_checkpoint_and_reaps_the_sim(tmp_path):
    namespace = f'/sigint_{time.monotonic_ns()}'
    process = subprocess.Popen(
        [ros2_run('nav_gym', 'train'), '--total-timesteps', '100000', '--learning-starts', '50',
         '--buffer-size', '1000', '--runs-dir', str(tmp_path), '--run-name', 'stop',
         '--sim', 'embedded', '--namespace', namespace],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    run_dir = tmp_path / 'stop'

    def learning() -> bool:  # under way once the first episode is in the Monitor CSV
        if monitor_rows(run_dir / 'monitor.csv'):
            return True
        assert process.poll() is None, process.communicate()
        return False

    wait_until(learning, 120, 'an episode in the Monitor CSV', interval=0.2)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 130, out + err
    assert 'interrupted at step' in out and 'Traceback' not in err
    assert f'continue with: nav-gym-train --resume {run_dir}' in out
    steps = checkpoints(run_dir)[-1][0]
    assert steps > 0
    assert json.loads((run_dir / 'summary.json').read_text())['interrupted'] is True
    assert leftover_sims(namespace) == []


def test_config_file_and_flags_override_defaults(tmp_path):
    path = tmp_path / 'train.yaml'
    path.write_text('learning_rate: 0.0005\ntotal_timesteps: 1000\n')
    config = build(str(path), {'total_timesteps': '2000'})
    assert (config.learning_rate, config.total_timesteps, config.gamma) == (5e-4, 2000, 0.99)
    with pytest.raises(TrainConfigError, match='unknown setting'):
        build(None, {'learning_rat': 1})
    path.write_text('batch_size: many\n')
    with pytest.raises(TrainConfigError, match='batch_size takes an integer'):
        build(str(path), {})


def test_settings_convert_as_every_other_setting_does():
    """One conversion (nav_sim.core.config.convert): '4.0' is 4; 3.7 and 'yes' are errors."""
    config = build(None, {'batch_size': '4.0', 'keep_replay_buffer': 'TRUE',
                          'learning_rate': '5e-4', 'goal_reward': '10'})
    assert (config.batch_size, config.keep_replay_buffer) == (4, True)
    assert (config.learning_rate, config.goal_reward) == (5e-4, 10.0)
    for key, value in (('batch_size', 3.7), ('batch_size', '3.7'), ('keep_replay_buffer', 'yes'),
                       ('batch_size', True), ('learning_rate', 'fast')):
        with pytest.raises(TrainConfigError, match=key):
            build(None, {key: value})


def test_a_run_saves_its_whole_env_config(tmp_path):
    """Reward weights and every other EnvConfig field travel with the run's config.yaml."""
    from nav_gym.env.config import EnvConfig
    from nav_gym.training.run_dir import load_config
    config = TrainConfig(goal_reward=10.0, step_penalty=-0.05, probe_timeout=0.5)
    assert {f.name for f in dataclasses.fields(EnvConfig)} <= set(dataclasses.asdict(config))
    env = config.env_config()
    assert (env.goal_reward, env.step_penalty, env.probe_timeout) == (10.0, -0.05, 0.5)
    (tmp_path / 'config.yaml').write_text(config.to_yaml())
    assert load_config(tmp_path) == config
    # a run from before these settings existed still loads, with the defaults of that time
    (tmp_path / 'config.yaml').write_text('learning_rate: 0.0001\nforward_speed: 0.12\n')
    assert load_config(tmp_path).env_config() == EnvConfig()
    # it trained SB3's DQN: the default of double_q has changed since, not the run
    assert load_config(tmp_path).double_q is False and TrainConfig().double_q is True
    assert load_config(tmp_path).n_steps == 1 and TrainConfig().n_steps == 3
    assert load_config(tmp_path).learner().vanilla and load_config(tmp_path).gradient_steps == 1


def test_the_workshop_config_is_sb3_dqn_exactly_and_sets_only_the_learner():
    import yaml

    from nav_gym.training.spec import COMPONENTS
    path = REPO / 'config' / 'workshop.yaml'
    config = build(str(path), {})
    assert config.learner().vanilla and not TrainConfig().learner().vanilla
    assert (config.gradient_steps, TrainConfig().gradient_steps) == (1, 2)  # SB3's, L5's
    assert set(yaml.safe_load(path.read_text())) <= {'double_q', 'gradient_steps', *COMPONENTS}


def test_train_yaml_holds_every_default():
    import dataclasses

    import yaml

    from nav_gym.training.config import TrainConfig
    source = REPO / 'config' / 'train.yaml'  # installed by make setup
    values = yaml.safe_load(source.read_text())
    defaults = dataclasses.asdict(TrainConfig())
    assert defaults['max_episode_steps'] == 100  # 0 in the file: the world's limit (arena's)
    assert values == {**defaults, 'max_episode_steps': 0}


@pytest.mark.parametrize('preset, expected', [(None, 'PASSIVE'), ('ACTIVE', 'ACTIVE')])
def test_learner_threads_wait_passively_unless_the_user_chose(preset, expected):
    code = ('from nav_gym.training.timing import quiet_learner_threads\n'
            'p = quiet_learner_threads()\n'
            'import os, torch; print(p, os.environ["OMP_WAIT_POLICY"])')
    env = {k: v for k, v in os.environ.items() if k != 'OMP_WAIT_POLICY'}
    if preset:
        env['OMP_WAIT_POLICY'] = preset
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [expected, expected]


def test_a_run_config_spells_out_every_sim_parameter():
    config = TrainConfig(sim_params={'camera_pitch_deg': 10, 'publish_clock': True})
    full = config.with_full_sim_params().sim_params
    assert full == {**dataclasses.asdict(SimConfig(camera_pitch_deg=10.0)),
                    'publish_clock': True}
    with pytest.raises(TrainConfigError, match='bogus'):
        TrainConfig(sim_params={'bogus': 1}).with_full_sim_params()
    with pytest.raises(TrainConfigError, match='sim_dt'):
        TrainConfig(sim_params={'sim_dt': 'fast'}).with_full_sim_params()
