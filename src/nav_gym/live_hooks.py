"""Hooks of the live view and the step time budget for the commands (light imports only).

``--live [PORT]`` for nav-gym-train, nav-eval-evaluate, visnav-pipeline and the demo; the
learner's share of the step budget; the training statistics callback.  The live view itself
(:mod:`nav_gym.live_view`, Foxglove) is imported only when it is switched on.
"""

from __future__ import annotations

import argparse
from typing import Any

from nav_sim.config import LIVE_DEFAULT_PORT as DEFAULT_LIVE_PORT


def add_live_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--live [PORT]``: serve a Foxglove live view (off by default)."""
    parser.add_argument('--live', nargs='?', type=int, const=DEFAULT_LIVE_PORT, default=0,
                        metavar='PORT', help='serve a Foxglove live view on ws://localhost:PORT '
                        f'(default port {DEFAULT_LIVE_PORT}; layout: '
                        'config/foxglove/visnav.json)')


def timed_dqn(timing: Any | None, double_q: bool = False) -> type:
    """Return a DQN class that counts its gradient steps and predictions into ``timing``.

    ``timing`` is the env's step budget (``env.timing``): SB3's ``train`` (gradient steps) and
    ``predict`` calls become the learner's share of every env step.  A subclass, not wrappers
    set on the model, so the timing never becomes model state that saving would pickle; a
    checkpoint of it loads with ``DQN.load`` as any other.  The learner is SB3's DQN, or with
    ``double_q`` :class:`nav_gym.double_dqn.DoubleDQN` (a diagnosis, not the workshop's
    learner); without ``timing`` that class itself is returned, untimed.
    """
    import time

    if double_q:
        from nav_gym.double_dqn import DoubleDQN as DQN
    else:
        from stable_baselines3 import DQN
    if timing is None:
        return DQN

    class TimedDQN(DQN):
        """The learner (SB3's DQN or Double DQN) with its ``train`` and ``predict`` timed."""

        def train(self, *args: Any, **kwargs: Any) -> Any:
            """Run SB3's gradient steps, timed as ``gradient_step``."""
            start = time.perf_counter()
            try:
                return super().train(*args, **kwargs)
            finally:
                timing.add('gradient_step', time.perf_counter() - start)

        def predict(self, *args: Any, **kwargs: Any) -> Any:
            """Run SB3's ``predict``, timed as ``predict``."""
            start = time.perf_counter()
            try:
                return super().predict(*args, **kwargs)
            finally:
                timing.add('predict', time.perf_counter() - start)

    return TimedDQN


def training_callback(env: Any) -> Any:
    """Return an SB3 callback that sends the learner's progress to the env's live view.

    Step, epsilon and the rolling return and success rate go on ``/visnav/training``; nothing is
    built while nobody watches (or without a live view).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    class LiveTraining(BaseCallback):
        """Send the learner's progress to the live view after every env step."""

        def _on_step(self) -> bool:
            if env.live is not None:
                env.live.log_training(self.num_timesteps, float(self.model.exploration_rate))
            return True

    return LiveTraining()
