"""The reward as a pure function of a step: its named terms (no ROS, no MuJoCo, no torch)."""

from __future__ import annotations

from nav_gym.env.config import EnvConfig
from nav_sim.core.events import EVENT_COLLISION, EVENT_GOAL


def reward_terms(previous_distance: float, distance: float, event: str,
                 config: EnvConfig) -> dict[str, float]:
    """Return the workshop reward term by term.

    The terms are progress, step cost, goal bonus and collision penalty.
    """
    progress = previous_distance - distance
    return {
        'progress': config.progress_weight * progress,
        'step': config.step_penalty,
        'goal': config.goal_reward if event == EVENT_GOAL else 0.0,
        'collision': config.collision_penalty if event == EVENT_COLLISION else 0.0,
    }
