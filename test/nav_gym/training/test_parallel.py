"""Parallel sims (``n_envs``): scenario streams, concurrent steps, the replay ratio, resume.

A 2-env training checkpoints, stops on Ctrl-C and resumes like a 1-env one.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from fractions import Fraction
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from helpers import wait_until
from nav_gym.errors import TrainConfigError
from nav_gym.training.config import TrainConfig, vector_schedule
from nav_gym.training.parallel import DERIVED_SEED_BIT, ParallelEnvs, env_seeds
from nav_gym.training.run_dir import checkpoints

TRAIN = str(Path(sys.prefix) / 'bin' / 'nav-gym-train')


class ScenarioEnv(gym.Env):
    """Draws its scenario seeds as NavigationEnv does: the reset seed, then its np_random."""

    observation_space = spaces.Box(0, 255, (3, 4, 4), np.uint8)
    action_space = spaces.Discrete(3)

    def __init__(self, barrier: threading.Barrier | None = None) -> None:
        self.barrier = barrier
        self.scenarios: list[int] = []
        self.steps = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.scenarios.append(seed if seed is not None
                              else int(self.np_random.integers(0, 2**31 - 1)))
        self.steps = 0
        return np.zeros((3, 4, 4), np.uint8), {}

    def step(self, action):
        if self.barrier is not None:  # every env must be inside step() at the same time
            self.barrier.wait(timeout=20)
        self.steps += 1
        return np.zeros((3, 4, 4), np.uint8), 0.0, False, self.steps >= 3, {}


def streams(seed: int, n_envs: int, episodes: int = 5) -> list[list[int]]:
    envs = ParallelEnvs([ScenarioEnv for _ in range(n_envs)])
    try:
        envs.seed(seed)
        envs.reset()
        for _ in range(3 * (episodes - 1)):
            envs.step(np.zeros(n_envs, dtype=np.int64))
        return [env.scenarios for env in envs.envs]
    finally:
        envs.close()


def test_envs_have_distinct_scenario_streams_and_a_seed_repeats_them():
    first = streams(1, 3)
    assert first == streams(1, 3)  # the same seed: the same streams
    assert first[0] == streams(1, 1)[0]  # env 0 is what one env always was
    assert first[0][0] == 1 and all(len(set(s)) == 5 for s in first)
    assert len({tuple(s) for s in first}) == 3
    # no env of one seed replays an env of another: seed 1's second env is not seed 2's first
    second = streams(2, 3)
    assert not {tuple(s) for s in first} & {tuple(s) for s in second}
    # the derived seeds: unique over seeds x envs, and never a run's own seed (< 2**32)
    derived = [s for seed in range(200) for s in env_seeds(seed, 8)[1:]]
    assert len(set(derived)) == len(derived)
    assert all(s >= DERIVED_SEED_BIT and s < 2**63 for s in derived)
    assert [env_seeds(seed, 8)[0] for seed in (0, 7, 2**32 - 1)] == [0, 7, 2**32 - 1]


def test_step_async_reaches_every_env_before_a_result_is_awaited():
    barrier = threading.Barrier(4)
    envs = ParallelEnvs([lambda: ScenarioEnv(barrier) for _ in range(4)])
    try:
        envs.reset()
        _, _, dones, infos = envs.step(np.array([0, 1, 2, 1]))  # a serial step: BrokenBarrier
        assert not dones.any() and envs.env_seconds > 0
        for _ in range(2):
            _, _, dones, infos = envs.step(np.array([0, 1, 2, 1]))
        assert dones.all()  # the third step truncates: ended, reset, as DummyVecEnv does
        assert all(info['TimeLimit.truncated'] and 'terminal_observation' in info
                   for info in infos)
    finally:
        envs.close()


def test_a_failed_env_step_raises_after_the_others_end_their_step():
    class Failing(ScenarioEnv):
        def step(self, action):
            raise RuntimeError('sim gone')

    slow = ScenarioEnv()
    ended = threading.Event()
    original = slow.step

    def slow_step(action):
        time.sleep(0.3)
        result = original(action)
        ended.set()
        return result

    slow.step = slow_step
    envs = ParallelEnvs([Failing, lambda: slow])
    envs.reset()
    with pytest.raises(RuntimeError, match='sim gone'):
        envs.step(np.array([1, 1]))
    assert ended.is_set()  # nothing closes an env under a step still under way
    envs.close()


def test_close_never_closes_an_env_under_a_step_still_under_way():
    release = threading.Event()

    class Stuck(ScenarioEnv):
        closed = stopped = False

        def step(self, action):
            release.wait(timeout=20)
            return super().step(action)

        def close(self):
            self.closed = True

        def stop_sim(self):
            self.stopped = True

    envs = ParallelEnvs([Stuck, Stuck], settle_seconds=0.2)
    envs.reset()
    envs.step_async(np.array([1, 1]))
    envs.close()  # the steps outlast the settle time: only their sims are stopped
    assert all(env.stopped and not env.closed for env in envs.envs)
    release.set()
    idle = ParallelEnvs([Stuck, Stuck], settle_seconds=0.2)
    idle.close()
    assert all(env.closed and not env.stopped for env in idle.envs)


def test_a_failed_env_build_closes_the_envs_already_built():
    closed = []

    class Closing(ScenarioEnv):
        def close(self):
            closed.append(self)

    def broken():
        time.sleep(0.2)
        raise RuntimeError('no sim')

    with pytest.raises(RuntimeError, match='no sim'):
        ParallelEnvs([Closing, broken, Closing])
    assert len(closed) == 2


@pytest.mark.parametrize('train_freq, gradient_steps', [(4, 1), (1, 1), (8, 3), (2, 5)])
@pytest.mark.parametrize('n_envs', [1, 2, 3, 4, 8])
def test_n_envs_keep_the_replay_ratio(train_freq, gradient_steps, n_envs):
    freq, steps = vector_schedule(train_freq, gradient_steps, n_envs)
    assert Fraction(steps, freq * n_envs) == Fraction(gradient_steps, train_freq)
    if n_envs == 1:
        assert (freq, steps) == (train_freq, gradient_steps)  # one env: as configured
    config = TrainConfig(n_envs=n_envs, train_freq=train_freq, gradient_steps=gradient_steps)
    assert (config.dqn_kwargs()['train_freq'], config.dqn_kwargs()['gradient_steps']) == (
        freq, steps)


def test_n_envs_settings_refused_in_one_line_and_namespaces():
    with pytest.raises(TrainConfigError, match='prioritized_replay supports n_envs 1'):
        TrainConfig(n_envs=2, prioritized_replay=True)
    with pytest.raises(TrainConfigError, match="sim must be 'auto' or 'embedded'"):
        TrainConfig(n_envs=2, sim='attach')
    configs = TrainConfig(n_envs=3, namespace='/lab').env_configs()
    assert [c.namespace for c in configs] == ['/lab/env0', '/lab/env1', '/lab/env2']
    assert {c.sim for c in configs} == {'embedded'}
    assert TrainConfig().env_configs() == [TrainConfig().env_config()]


def test_two_envs_checkpoint_stop_on_ctrl_c_and_resume(tmp_path):
    namespace = f'/parallel_{time.monotonic_ns()}'
    run_dir = tmp_path / 'two'
    common = ['--learning-starts', '50', '--buffer-size', '1000', '--checkpoint-freq', '150']
    process = subprocess.Popen(
        [TRAIN, '--total-timesteps', '100000', *common, '--runs-dir', str(tmp_path),
         '--run-name', 'two', '--n-envs', '2', '--namespace', namespace],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def sims() -> list[str]:
        out = subprocess.run(['pgrep', '-af', namespace], capture_output=True, text=True).stdout
        return [line for line in out.splitlines() if 'pgrep' not in line and 'sim_node' in line]

    def past_a_checkpoint() -> bool:
        if [s for s, _ in checkpoints(run_dir) if s > 0]:
            return True
        assert process.poll() is None, process.communicate()
        return False

    wait_until(past_a_checkpoint, 240, 'a checkpoint after step 0', interval=0.2)
    assert {f'{namespace}/env0', f'{namespace}/env1'} <= {
        word.split(':=')[-1] for line in sims() for word in line.split()}
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 130, out + err
    assert 'interrupted at step' in out and 'Traceback' not in err
    stopped = checkpoints(run_dir)[-1][0]
    assert stopped >= 150 and stopped % 2 == 0  # two env steps per vector step
    summary = json.loads((run_dir / 'summary.json').read_text())
    assert summary['interrupted'] is True and summary['n_envs'] == 2
    wait_until(lambda: not sims(), 30, 'no sim process of the run left')

    refused = subprocess.run([TRAIN, '--resume', str(run_dir), '--n-envs', '1'],
                             capture_output=True, text=True, timeout=120)
    assert refused.returncode == 1 and 'n_envs 2' in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1

    total = stopped + 100
    result = subprocess.run([TRAIN, '--resume', str(run_dir), '--total-timesteps', str(total)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert f'(step {stopped}) with its replay buffer' in result.stdout
    assert checkpoints(run_dir)[-1][0] >= total
    summary = json.loads((run_dir / 'summary.json').read_text())
    assert summary['outcome'] == 'finished' and len(summary['sessions']) == 2
    assert summary['episodes'] > 0
    rows = (run_dir / 'monitor.csv').read_text().splitlines()
    assert rows[0].startswith('#{') and rows[1].startswith('r,l,t')
    assert all(len(row.split(',')) == 5 for row in rows[2:])  # whole rows, never interleaved
    assert not sims()
