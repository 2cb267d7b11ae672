"""Write the live view's episode topics into an evaluation bag (no rclpy).

An env observer (``NavigationEnv.observers``) that writes, at each frame's sim stamp, what the
live view shows of an episode: ``/visnav/scene`` at every reset, ``/visnav/robot`` (robot,
heading, camera frustum, path), ``/visnav/observation`` and ``/visnav/step`` (action, reward
terms, distance, event, Q-values) every step.  With the camera image and the episode events the
recorder takes from the graph (under their root names), a recorded episode replays in the
shipped Foxglove layout (``config/foxglove/visnav.json``) as it looked live.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nav_gym.env.observers import EpisodeObserver
from nav_sim.viz import topics as live_topics
from nav_sim.viz.topics import OBSERVATION_TOPIC, ROBOT_TOPIC, SCENE_TOPIC, STEP_TOPIC


class BagSceneWriter(EpisodeObserver):
    """Write the scene, robot, observation and step of every env frame with ``recorder.write``."""

    def __init__(self, recorder: Any, sim_params: dict[str, Any] | None = None) -> None:
        """Write into ``recorder`` (a :class:`nav_eval.recording.recorder.BagRecorder`)."""
        super().__init__(sim_params)
        self.recorder = recorder

    def _write(self, topic: str, msg: Any, stamp_ns: int) -> None:
        msgtype = live_topics.TOPIC_TYPES[topic]
        self.recorder.write(topic, msgtype, live_topics.to_cdr(msg, msgtype), stamp_ns)

    def on_reset(self, stamp_ns: int, rgb: np.ndarray, obs: np.ndarray,
                 info: dict[str, Any]) -> None:
        """Write the episode's scene, the robot at its start and the first observation."""
        self.begin_episode(info)
        self._write(SCENE_TOPIC, self.scene.scene(stamp_ns), stamp_ns)
        self._write(ROBOT_TOPIC, self.scene.robot(stamp_ns), stamp_ns)
        self._write(OBSERVATION_TOPIC, live_topics.observation_image(obs, stamp_ns), stamp_ns)

    def on_step(self, stamp_ns: int, rgb: np.ndarray, obs: np.ndarray, action: int,
                reward: float, info: dict[str, Any], done: bool) -> None:
        """Write the robot, the observation and the step's numbers."""
        q_values = self.follow_step(reward, info)
        self._write(ROBOT_TOPIC, self.scene.robot(stamp_ns), stamp_ns)
        self._write(OBSERVATION_TOPIC, live_topics.observation_image(obs, stamp_ns), stamp_ns)
        self._write(STEP_TOPIC, self.step_message(stamp_ns, action, reward, info, q_values),
                    stamp_ns)
