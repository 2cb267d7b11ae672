"""Hooks of the live view for the commands (light imports only).

``--live [PORT]`` for nav-gym-train, nav-eval-evaluate, visnav-pipeline and the demo, and the
training statistics callback.  The live view itself (:mod:`nav_gym.live_view`, Foxglove) is
imported only when it is switched on.
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
