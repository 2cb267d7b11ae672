"""Measure how much wall-clock time the environment takes (vs. the learner)."""

from __future__ import annotations

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
