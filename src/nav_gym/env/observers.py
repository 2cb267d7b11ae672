"""What an env observer keeps of an episode (no rclpy): the live view's and the bags' shared part.

``NavigationEnv.observers`` are told of every reset and step.  Both observers, the live view
(:class:`nav_gym.env.live_view.EnvLive`) and the evaluation bag's scene writer
(:class:`nav_eval.recording.scene.BagSceneWriter`), follow an episode the same way: its number,
its return so far, the policy's Q-values for the next step, the 3D scene with the robot's path,
and the ``/visnav/step`` message of each step.  They differ only in where the messages go.
"""

from __future__ import annotations

from typing import Any

from nav_sim.viz import topics as live_topics
from nav_sim.viz.server import EpisodeScene


class EpisodeObserver:
    """Keep one env's episode: number, return, pending Q-values and the scene with the path."""

    def __init__(self, sim_params: dict[str, Any] | None = None) -> None:
        """Read the arena of the env's sim settings (loads the MJCF only)."""
        self.scene = EpisodeScene(live_topics.arena_for(sim_params))
        self.episode = 0
        self.episode_return = 0.0
        self.q_values: Any = None

    def note_q_values(self, q_values: Any) -> None:
        """Attach the policy's Q-values to the next step (evaluation)."""
        self.q_values = q_values

    def begin_episode(self, info: dict[str, Any]) -> None:
        """Count a new episode from its reset ``info``: return 0, the scene at the start pose."""
        self.episode += 1
        self.episode_return = 0.0
        self.scene.reset(info['scenario'], info['pose'])

    def follow_step(self, reward: float, info: dict[str, Any]) -> Any:
        """Add a step's reward and pose; return (and forget) the Q-values noted for it."""
        self.episode_return += reward
        self.scene.step(info['pose'])
        q_values, self.q_values = self.q_values, None
        return q_values

    def step_message(self, stamp_ns: int, action: int, reward: float, info: dict[str, Any],
                     q_values: Any) -> Any:
        """Return the ``/visnav/step`` message of a followed step."""
        return live_topics.env_step(
            stamp_ns, self.episode, info['step'], action, info['action_name'], reward,
            info['reward_terms'], self.episode_return, info['distance'], info['event'],
            q_values)
