"""The controller: the newest image in, a command (or a stop) out at every decision (no ROS).

The observation is the env's own (:func:`nav_gym.env.observation.image_msg_to_observation`);
the actor (:class:`nav_gym.policy.actors.Actor`) chooses the action.  Without an image newer
than ``image_timeout`` the command is a stop.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from nav_gym.env.actions import ACTION_NAMES
from nav_gym.env.observation import image_msg_to_observation
from nav_gym.errors import ObservationError
from nav_gym.policy.actors import Acting, Actor

STOP = -1  # the action of a stop command (no usable image): zero velocity


@dataclass(frozen=True)
class Command:
    """One decision: the cmd_vel to publish and what it was made of."""

    linear: float
    angular: float
    action: int                          # STOP (-1) when there is no usable image
    q_values: tuple[float, ...] | None
    stamp: Any                           # the decided image's header stamp (None: no image)
    image_age_s: float                   # wall-clock seconds since that image arrived
    inference_s: float                   # observation + network; 0 for a repeated decision
    observation: np.ndarray | None
    reason: str                          # 'decided', 'repeated', 'no image', 'stale', 'bad image',
    #                                      'new episode' (the newest image is from before it)
    frame_id: str = ''                   # the decided image's frame

    @property
    def stopped(self) -> bool:
        """Tell whether this is a stop (zero velocity) for want of a usable image."""
        return self.action == STOP

    def values(self, stamp_age_s: float) -> list[float]:
        """Return the decision message's values, in ``nav_sim.interface.DECISION_FIELDS`` order."""
        q = self.q_values or ()
        q_values = [float(q[i]) if i < len(q) else math.nan for i in range(len(ACTION_NAMES))]
        return [float(self.action), self.linear, self.angular, *q_values,
                1e3 * self.image_age_s, 1e3 * stamp_age_s, 1e3 * self.inference_s]


class Controller:
    """Keep the newest image; at each decision, turn it into a command (or a stop).

    Every image is kept as it arrives and converted only when a decision uses it; a decision
    on the same image as the one before repeats that command without converting again (the
    policies are deterministic).  ``clock`` gives wall-clock seconds (injectable for tests).
    """

    def __init__(self, actor: Actor, acting: Acting, image_timeout: float,
                 clock: Any = time.monotonic) -> None:
        """Act with ``actor``; stop when the newest image is older than ``image_timeout`` s."""
        self.actor = actor
        self.twists = acting.twists
        self.image_timeout = image_timeout
        self.clock = clock
        self._image: Any = None
        self._received = -math.inf
        self._last: Command | None = None
        self._last_image: Any = None
        self.image_error = ''  # why the newest image could not be converted
        self._stopped_stale = False
        self._before: Callable[[Any], bool] = lambda msg: False
        self.begin_episode(None)  # the node's first episode starts with it (seed unknown)

    def begin_episode(self, seed: int | None,
                      before: Callable[[Any], bool] | None = None) -> None:
        """Start an episode: the actor's memory (a frame history) begins at its first image.

        The node calls it at the sim's reset event, at its ``policy/begin_episode`` service and
        here after a stale-image stop: what the robot saw before the gap is no history to act on.
        ``before`` tells whether an image was taken before the episode (the node's reset event
        compares stamps: the reset frame shares the event's, whichever topic arrives first); by
        default the newest image now is the last one before it.  Until the episode's first
        image comes, decisions are stops ('new episode'): an image of the episode before is
        not acted on, and does not begin the memory.
        """
        self.actor.begin_episode(seed)
        self._last = self._last_image = None
        if before is None:
            newest = self._image
            before = lambda msg: msg is newest  # noqa: E731 - the image newest now
        self._before = before

    def on_image(self, msg: Any, received: float | None = None) -> None:
        """Keep ``msg`` (a sensor_msgs/Image) as the newest image, received now by default."""
        self._image = msg
        self._received = self.clock() if received is None else received

    def decide(self, now: float | None = None) -> Command:
        """Return the command for the newest image (a stop if it is missing, stale or bad).

        Raises nothing for a bad image: its command is a stop with ``reason='bad image'``, and
        :attr:`image_error` says why.
        """
        now = self.clock() if now is None else now
        msg, age = self._image, now - self._received
        if msg is None:
            return self._stop('no image', None, math.nan)
        if age > self.image_timeout:
            if not self._stopped_stale:  # once per gap: the memory begins at the next image
                self._stopped_stale = True
                self.begin_episode(None)
            return self._stop('stale', msg.header, age)
        self._stopped_stale = False
        if self._before(msg):
            return self._stop('new episode', msg.header, age)
        last = self._last
        if msg is self._last_image and last is not None:
            return dataclasses.replace(last, image_age_s=age, inference_s=0.0,
                                       reason=last.reason if last.stopped else 'repeated')
        start = time.perf_counter()
        try:
            observation, _ = image_msg_to_observation(msg)
        except ObservationError as exc:
            self.image_error = str(exc)
            command = self._stop('bad image', msg.header, age)
        else:
            action, q_values = self.actor.act(observation)
            linear, angular = self.twists[action]
            command = Command(linear, angular, action, q_values, msg.header.stamp, age,
                              time.perf_counter() - start, observation, 'decided',
                              msg.header.frame_id)
        self._last, self._last_image = command, msg
        return command

    def _stop(self, reason: str, header: Any, age: float) -> Command:
        if header is None:
            return Command(0.0, 0.0, STOP, None, None, age, 0.0, None, reason)
        return Command(0.0, 0.0, STOP, None, header.stamp, age, 0.0, None, reason,
                       header.frame_id)
