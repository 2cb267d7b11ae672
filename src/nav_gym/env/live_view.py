"""The trainer's and evaluator's live view: what one env sees, sent to Foxglove (no rclpy).

With ``--live [PORT]`` the training or evaluation process hosts the one Foxglove server
(:class:`nav_sim.viz.server.LiveView`) and logs everything its env sees: the camera image it
received, the 84x84 observation, the 3D scene (from the reset's episode description and the pose in
``info``), the action, reward terms, distance and event of every step (``/visnav/step``, with
the Q-values in evaluation), the training statistics (``/visnav/training``) and the env's time
budget (``/diagnostics``).  The sim node the env starts keeps its own ``live_port`` off.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from nav_gym.env.observers import EpisodeObserver
from nav_sim.core.events import EVENT_GOAL
from nav_sim.viz import topics as live_topics
from nav_sim.viz.server import LiveView

ROLLING_EPISODES = 100   # SB3's ep_info_buffer length: the same rolling window as its logger


class EnvLive(EpisodeObserver):
    """Log one env's resets and steps to a live view."""

    def __init__(self, port: int, sim_params: dict[str, Any] | None = None,
                 topics: tuple[str, ...] = live_topics.ENV_TOPICS) -> None:
        """Start the server on ``port`` and read the arena of the env's sim settings.

        ``topics``: what the server advertises (a closed-loop evaluation adds the policy
        node's, :data:`nav_sim.viz.topics.CLOSED_LOOP_TOPICS`, sent with :meth:`forward`).
        """
        self.view = LiveView(port, topics, name='visnav env')
        super().__init__(sim_params)
        self.stamp_ns = 0
        self._returns: deque[float] = deque(maxlen=ROLLING_EPISODES)
        self._successes: deque[float] = deque(maxlen=ROLLING_EPISODES)
        self._lengths: deque[int] = deque(maxlen=ROLLING_EPISODES)

    @property
    def url(self) -> str:
        """The ``ws://`` address viewers open."""
        return self.view.url

    def on_reset(self, stamp_ns: int, rgb: np.ndarray, obs: np.ndarray,
                 info: dict[str, Any]) -> None:
        """Log the first frame of an episode and its scene."""
        self.begin_episode(info)
        self.stamp_ns = stamp_ns
        self._images(stamp_ns, rgb, obs)
        self.scene.log(self.view, stamp_ns, new_episode=True)

    def on_step(self, stamp_ns: int, rgb: np.ndarray, obs: np.ndarray, action: int,
                reward: float, info: dict[str, Any], done: bool) -> None:
        """Log one step: images, robot and path, and the step's action, rewards and event."""
        view = self.view
        self.stamp_ns = stamp_ns
        q_values = self.follow_step(reward, info)
        self._images(stamp_ns, rgb, obs)
        self.scene.log(view, stamp_ns, new_episode=False)
        view.log(live_topics.STEP_TOPIC,
                 lambda: self.step_message(stamp_ns, action, reward, info, q_values), stamp_ns,
                 force=done)
        if done:
            self._returns.append(self.episode_return)
            self._successes.append(1.0 if info['event'] == EVENT_GOAL else 0.0)
            self._lengths.append(int(info['step']))
    def _images(self, stamp_ns: int, rgb: np.ndarray, obs: np.ndarray) -> None:
        view = self.view
        view.log(live_topics.CAMERA_TOPIC,
                 lambda: live_topics.image(rgb, stamp_ns, 'camera_optical_frame'), stamp_ns)
        view.log(live_topics.OBSERVATION_TOPIC,
                 lambda: live_topics.observation_image(obs, stamp_ns), stamp_ns)

    def log_training(self, num_timesteps: int, exploration_rate: float) -> None:
        """Log the learner's progress with the rolling return and success rate."""
        def message() -> Any:
            return live_topics.training_stats(
                self.stamp_ns, num_timesteps, self.episode, exploration_rate,
                float(np.mean(self._returns)) if self._returns else 0.0,
                float(np.mean(self._successes)) if self._successes else 0.0,
                float(np.mean(self._lengths)) if self._lengths else 0.0)
        self.view.log(live_topics.TRAINING_TOPIC, message, self.stamp_ns)

    def log_diagnostics(self, cdr: bytes) -> None:
        """Send a ``/diagnostics`` message (CDR) if a viewer wants it."""
        self.view.log_cdr(live_topics.DIAGNOSTICS_TOPIC, lambda: cdr, self.stamp_ns)

    def forward(self, topic: str, cdr: bytes, stamp_ns: int | None = None) -> None:
        """Send a graph message (CDR) on one of the advertised topics if a viewer wants it."""
        self.view.log_cdr(topic, lambda: cdr, self.stamp_ns if stamp_ns is None else stamp_ns)

    def close(self) -> None:
        """Stop the server."""
        self.view.close()

