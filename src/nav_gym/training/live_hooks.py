"""The training statistics callback of the live view (light imports only).

``--live [PORT]`` itself is :func:`nav_sim.viz.options.add_live_argument`.  The live view
(:mod:`nav_gym.env.live_view`, Foxglove) is imported only when it is switched on.
"""

from __future__ import annotations

from typing import Any


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
