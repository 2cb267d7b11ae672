"""Measure how much wall-clock time the environment takes (vs. the learner)."""

from __future__ import annotations

import os
import sys
import time
from typing import Any

import gymnasium as gym


class EnvTimer(gym.Wrapper):
    """Accumulates the seconds spent inside ``reset()`` and ``step()``."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.env_seconds = 0.0
        self.env_steps = 0

    def reset(self, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return self.env.reset(**kwargs)
        finally:
            self.env_seconds += time.perf_counter() - start

    def step(self, action: Any) -> Any:
        start = time.perf_counter()
        try:
            return self.env.step(action)
        finally:
            self.env_seconds += time.perf_counter() - start
            self.env_steps += 1


def quiet_learner_threads() -> str:
    """Let PyTorch's OpenMP threads sleep between learning steps instead of spinning.

    libgomp keeps idle worker threads spinning for a while after each parallel region.  With
    ``train_freq`` 4 the learner's threads then spin through the env steps in between and take
    the CPU from the sim process.  ``benchmarks/bench_env.py`` compares both on 2 cores: the
    env's share of DQN training time was 19 % with passive waits against 22 % with spinning;
    the total wall-clock time did not differ beyond the run-to-run noise (about 10 %).

    Call it before torch is first imported (OpenMP reads the variable once).  A policy the user
    set wins.  Returns the policy in effect, recorded with a run's timing figures.
    """
    if 'OMP_WAIT_POLICY' not in os.environ and 'torch' not in sys.modules:
        os.environ['OMP_WAIT_POLICY'] = 'PASSIVE'
    return os.environ.get('OMP_WAIT_POLICY', 'default (torch was imported first)')
