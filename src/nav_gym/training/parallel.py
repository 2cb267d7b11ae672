"""Parallel sims for training: N envs, each driving its own sim process, stepped concurrently.

``n_envs: N`` (config/train.yaml) trains on N :class:`~nav_gym.env.navigation.NavigationEnv`
clients, each with its own sim process in its own namespace, through SB3's VecEnv API.  The
envs live in the learner's process (the sims are the processes that do the work); a thread per
env sends its ``cmd_vel`` and waits for its frame, so ``step_async`` has reached all N sims
before any result is awaited and the N control periods run at the same time.  With one env
nothing changes: :class:`ParallelEnvs` then steps as SB3's ``DummyVecEnv``, which SB3 would
have built around the env anyway, and training is bit for bit what it was.

Scenario streams (:func:`env_seeds`): env 0 is seeded with the run's seed, as one env always
was; env ``i > 0`` with a seed drawn from ``SeedSequence(seed, spawn_key=(i,))`` with bit 62 set.
No run's seed (``< 2**32``) has that bit, so no env ``i > 0`` replays any run's env 0 (seed 1's
second env is not seed 2's first), the spawn keys keep the envs of one run apart, and the same
seed always gives the same streams.

No rclpy and no torch here: the envs are built by the callables the trainer passes.
"""

from __future__ import annotations

import concurrent.futures
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import Monitor, ResultsWriter
from stable_baselines3.common.vec_env import DummyVecEnv

#: env i > 0 draws its seed with this bit set: a run's own seed (< 2**32) never has it
DERIVED_SEED_BIT = 1 << 62
#: seconds a stopped vector step or build waits for the other envs to end theirs (the trainer
#: passes more when the envs' sim_timeout asks for it: ParallelEnvs(settle_seconds=...))
SETTLE_SECONDS = 30.0


def env_seeds(seed: int | None, n_envs: int) -> list[int]:
    """Return the reset seed of each of ``n_envs`` envs: ``seed`` first, then derived ones.

    See the module docstring; ``None`` draws the first seed as SB3's ``VecEnv.seed`` does.
    """
    if seed is None:
        seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
    seeds = [int(seed)]
    for index in range(1, n_envs):
        words = np.random.SeedSequence(int(seed), spawn_key=(index,)).generate_state(2)
        value = (int(words[0]) << 32 | int(words[1])) & (DERIVED_SEED_BIT - 1)
        seeds.append(DERIVED_SEED_BIT | value)
    return seeds


def _build_all(env_fns: Sequence[Callable[[], gym.Env]],
               pool: concurrent.futures.ThreadPoolExecutor | None,
               settle_seconds: float) -> list[gym.Env]:
    """Call every builder (in ``pool``'s threads when given); close what was built on failure."""
    if pool is None:
        return [make() for make in env_fns]
    futures = []
    try:
        for make in env_fns:
            futures.append(pool.submit(make))
        return [future.result() for future in futures]
    except BaseException:
        concurrent.futures.wait(futures, timeout=settle_seconds)
        for future in futures:
            if future.done() and future.exception() is None:
                future.result().close()
        pool.shutdown(wait=False, cancel_futures=True)
        raise


class MonitorFile(ResultsWriter):
    """The run's monitor.csv: SB3's ``ResultsWriter`` that the Monitors of all envs share.

    Rows are written whole, one at a time (the envs step in their own threads); every Monitor
    counts its episodes' times from this file's ``t_start``.  ``append`` continues a resumed
    run's file (SB3 writes the header only for a new one).
    """

    def __init__(self, path: str, append: bool, info_keywords: tuple[str, ...]) -> None:
        """Open (or create) the CSV file."""
        self.t_start = time.time()
        self.info_keywords = info_keywords
        super().__init__(path, header={'t_start': self.t_start, 'env_id': 'None'},
                         extra_keys=info_keywords, override_existing=not append)
        self._lock = threading.Lock()

    def write_row(self, epinfo: dict[str, float]) -> None:
        """Write one episode's row (whole, never interleaved with another env's)."""
        with self._lock:
            super().write_row(epinfo)

    def monitor(self, env: gym.Env) -> Monitor:
        """Return ``Monitor(env)`` writing its episodes to this file."""
        monitor = Monitor(env, None, info_keywords=self.info_keywords)
        monitor.t_start = self.t_start
        monitor.results_writer = self
        return monitor


class ParallelEnvs(DummyVecEnv):
    """SB3's ``DummyVecEnv`` whose N envs step concurrently, one thread each (N > 1).

    Also what the trainer reads of its envs: the seconds spent stepping them
    (``env_seconds``), the first env (the live view and the step budget), the episode count
    and why a sim died.
    """

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]],
                 settle_seconds: float = SETTLE_SECONDS) -> None:
        """Build the envs at the same time (each starts its sim); on any failure close them all.

        ``settle_seconds``: how long a stopped step or build may take to end (more than the
        envs' own time-outs) before the envs are closed around it.
        """
        pool = None
        if len(env_fns) > 1:
            pool = concurrent.futures.ThreadPoolExecutor(len(env_fns), 'visnav_env')
        envs = _build_all(env_fns, pool, settle_seconds)
        try:
            super().__init__([lambda env=env: env for env in envs])
        except BaseException:
            for env in envs:
                env.close()
            raise
        self.env_seconds = 0.0
        self.settle_seconds = settle_seconds
        self._started = 0.0
        self._pool = pool
        #: the steps under way, by env index: close() never closes an env under its step
        self._pending: dict[int, concurrent.futures.Future] = {}

    @property
    def first(self) -> Any:
        """Return env 0 unwrapped (the live view, the step budget, the learner's timing)."""
        return self.envs[0].unwrapped

    def seed(self, seed: int | None = None) -> Sequence[None | int]:
        """Seed the envs' next reset with their scenario streams (:func:`env_seeds`)."""
        self._seeds = env_seeds(seed, self.num_envs)
        return self._seeds

    def reset(self) -> Any:
        """Reset every env (timed into ``env_seconds``)."""
        start = time.perf_counter()
        try:
            return super().reset()
        finally:
            self.env_seconds += time.perf_counter() - start

    def step_async(self, actions: np.ndarray) -> None:
        """Send each env its action; with N > 1 all N are under way when this returns."""
        self.actions = actions
        self._started = time.perf_counter()
        if self._pool is not None:
            for index in range(self.num_envs):  # each kept at once: close() waits for it
                self._pending[index] = self._pool.submit(self._step_env, index, actions[index])

    def step_wait(self) -> Any:
        """Collect the N steps (an ended episode's env is reset, as DummyVecEnv does)."""
        try:
            if self._pool is None:
                return super().step_wait()
            try:
                results = [self._pending[index].result() for index in range(self.num_envs)]
            except BaseException:
                # Ctrl-C, or one env failed: let the others end their step before anything
                # closes the envs under them (a sim that is gone times out in sim_timeout)
                self._settle()
                raise
            self._pending = {}
            for index, (obs, reward, done, info) in enumerate(results):
                self.buf_rews[index], self.buf_dones[index] = reward, done
                self.buf_infos[index] = info
                self._save_obs(index, obs)
            return (self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones),
                    [dict(info) for info in self.buf_infos])
        finally:
            self.env_seconds += time.perf_counter() - self._started

    def _step_env(self, index: int, action: Any) -> tuple[Any, float, bool, dict[str, Any]]:
        """Step env ``index`` (in its thread) and reset it when its episode ends."""
        env = self.envs[index]
        obs, reward, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        info['TimeLimit.truncated'] = truncated and not terminated
        if done:
            info['terminal_observation'] = obs
            obs, self.reset_infos[index] = env.reset()
        return obs, float(reward), bool(done), info

    def episode_count(self) -> int:
        """Return the episodes the envs' Monitors finished (all sessions of this process)."""
        return sum(len(env.get_episode_rewards()) for env in self.envs)

    def sim_failure(self) -> str | None:
        """Say why a sim an env started exited (which env, with more than one), else None."""
        for index, env in enumerate(self.envs):
            failure = env.unwrapped.sim_failure()
            if failure is not None:
                return failure if self.num_envs == 1 else f'env {index}: {failure}'
        return None

    def _settle(self) -> None:
        """Wait up to ``settle_seconds`` for the steps under way; forget those that ended."""
        concurrent.futures.wait(list(self._pending.values()), timeout=self.settle_seconds)
        self._pending = {i: f for i, f in self._pending.items() if not f.done()}

    def close(self) -> None:
        """Close every env and the sim it started, then stop the threads.

        An env whose step is still under way after ``settle_seconds`` only has its sim stopped
        (its step then fails at once and its thread ends): its client is never closed under it.
        The threads stop last: a sim started from a thread is also stopped when that thread
        exits (``SimProcess``'s parent-death signal).
        """
        self._settle()
        for index, env in enumerate(self.envs):
            if index in self._pending:
                env.unwrapped.stop_sim()
            else:
                env.close()
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
