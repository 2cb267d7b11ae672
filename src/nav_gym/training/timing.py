"""The learner's OpenMP threads: passive waits, so that they leave the CPU to the sim."""

from __future__ import annotations

import os
import sys


def quiet_learner_threads() -> str:
    """Let PyTorch's OpenMP threads sleep between learning steps instead of spinning.

    libgomp keeps idle worker threads spinning for a while after each parallel region.  With
    ``train_freq`` 4 the learner's threads then spin through the env steps in between and take
    the CPU from the sim process (and from each other when the cores are shared).  The default
    is chosen by wall-clock time, not by the env's share (a slower learner lowers the share):
    ``benchmarks/bench_env.py`` on 2 cores shared with other work (load average 4-9), 2,000
    DQN steps, 5 alternating runs each: passive 27-55 s (mean 41.5 s), libgomp's default
    102-271 s (mean 178 s).  On a quiet machine one earlier measurement had passive 14 % slower
    (65.5 s vs 57.5 s for 4,000 steps); spinning costs far more under contention than passive
    waits cost on an idle machine, so passive is the default.

    Call it before torch is first imported (OpenMP reads the variable once).  A policy the user
    set wins.  Returns the policy in effect, recorded with a run's timing figures.
    """
    if 'OMP_WAIT_POLICY' not in os.environ and 'torch' not in sys.modules:
        os.environ['OMP_WAIT_POLICY'] = 'PASSIVE'
    return os.environ.get('OMP_WAIT_POLICY', 'default (torch was imported first)')
