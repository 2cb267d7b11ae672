"""The closed-loop evaluation's view of a realtime sim driven by the policy node (rclpy).

A :class:`RealtimeGraph` is a client of the sim's services (:class:`nav_sim.ros.client.SimClient`:
seed and split, ``reset``, ``stop``) that publishes nothing: the policy node drives.  It
subscribes, with queues deep enough to lose nothing between two looks, to every period's
``episode_event`` and ``camera/image_raw`` and to every ``policy/decision``, and keeps each with
the wall-clock time its publisher sent it (DDS's source timestamp, which
:mod:`nav_eval.analysis.closed_loop` turns into the command in effect and the latency).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image, JointState

from nav_eval.analysis.closed_loop import Decision, Tick
from nav_eval.errors import EvaluationError
from nav_sim import interface
from nav_sim.ros import messages as ros_msgs
from nav_sim.ros import qos
from nav_sim.ros.client import SimClient
from nav_sim.viz import topics as live_topics

QUEUE_DEPTH = 200  # messages a subscription holds between two looks (seconds at any rate)
SPIN_S = 0.05
DRAIN_IDLE_CALLS = 4  # > the sim client's own subscriptions that may be ready at once


@dataclass(frozen=True)
class Period:
    """One control period: its tick and its image (with when the sim published the image)."""

    tick: Tick
    image: Image
    image_published_ns: int


def _deep(profile: QoSProfile) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=QUEUE_DEPTH,
                      reliability=profile.reliability, durability=profile.durability)


class RealtimeGraph:
    """Follow a realtime sim and the policy node driving it in ``namespace``."""

    def __init__(self, namespace: str, timeout: float = 10.0) -> None:
        """Create the client node (its own context) and its subscriptions."""
        self.client = SimClient(namespace, timeout=timeout, node_name='visnav_closed_loop')
        node = self.client.node
        self.ticks: dict[int, Tick] = {}
        self.images: dict[int, tuple[Image, int]] = {}
        self.decisions: list[Decision] = []
        #: called with (live topic, CDR bytes, stamp ns) for each decision and /diagnostics
        #: message, for a live view (None: not serialized at all)
        self.forward: Callable[[str, bytes, int | None], None] | None = None
        self._received = 0
        node.create_subscription(DiagnosticArray, interface.EVENT_TOPIC, self._on_event,
                                 _deep(qos.OBSERVATION))
        node.create_subscription(Image, interface.IMAGE_TOPIC, self._on_image,
                                 _deep(qos.OBSERVATION))
        # raw: a live view forwards the bytes as they came (rclpy's serialize_message pads
        # some messages, JointState among them, beyond what CDR readers such as rosbags take)
        self.sub_decisions = node.create_subscription(
            JointState, interface.DECISION_TOPIC, self._on_decision, _deep(qos.DECISIONS),
            raw=True)
        node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10,
                                 raw=True)

    # --- subscriptions --------------------------------------------------------------------
    def _on_event(self, msg: DiagnosticArray, info: dict[str, Any]) -> None:
        self._received += 1
        event = ros_msgs.parse_event(msg)
        if event is not None:
            stamp = ros_msgs.stamp_to_ns(msg.header.stamp)
            self.ticks[stamp] = Tick(stamp, int(info['source_timestamp']), event)

    def _on_image(self, msg: Image, info: dict[str, Any]) -> None:
        self._received += 1
        self.images[ros_msgs.stamp_to_ns(msg.header.stamp)] = (msg,
                                                               int(info['source_timestamp']))

    def _on_decision(self, data: bytes, info: dict[str, Any]) -> None:
        self._received += 1
        msg = deserialize_message(data, JointState)
        values = dict(zip(msg.name, msg.position, strict=False))
        stamp = ros_msgs.stamp_to_ns(msg.header.stamp)
        published = int(info['source_timestamp'])
        # a stop without any image carries the node's clock as its stamp: no image of ours
        self.decisions.append(Decision(stamp if stamp in self.images or values['action'] >= 0
                                       else None, published, values))
        if self.forward is not None:
            self.forward(live_topics.DECISION_TOPIC, data, stamp)

    def _on_diagnostics(self, data: bytes) -> None:
        if self.forward is not None:
            self.forward(live_topics.DIAGNOSTICS_TOPIC, data, None)

    # --- waiting --------------------------------------------------------------------------
    def spin_until(self, done: Callable[[], bool], limit: float) -> bool:
        """Process messages until ``done()`` or ``limit`` seconds; False on time-out."""
        return self.client.spin_until(done, limit)

    def drain(self) -> None:
        """Take every message that has arrived, without waiting for more.

        The client's node also has the sim client's own subscriptions (depth 1), whose
        callbacks count nothing here: a few calls in a row that add nothing mean all is taken.
        """
        idle = 0
        while idle < DRAIN_IDLE_CALLS:
            before = self._received
            self.client.spin_once(0.0)
            idle = idle + 1 if self._received == before else 0

    def wait_ready(self, timeout: float, abort: Callable[[], str | None]) -> None:
        """Block until the sim answers and the policy node drives it; raise with the reason.

        ``abort`` names a failed child process (the sim or the policy node), if one has died.
        """
        self.client.wait_for_sim(timeout, abort)
        node = self.client.node
        cmd_vel = node.resolve_topic_name(interface.CMD_VEL_TOPIC)
        deadline = time.monotonic() + timeout
        while not (node.count_publishers(cmd_vel) >= 1 and self.decisions):
            reason = abort()
            if reason:
                raise EvaluationError(f'the closed loop did not start: {reason}')
            if time.monotonic() > deadline:
                raise EvaluationError(f'the policy node published no decision in '
                                      f'{self.client.where} within {timeout} s')
            self.spin_until(lambda: bool(self.decisions), SPIN_S)

    def reset(self, seed: int, split: str, timeout: float) -> tuple[dict[str, Any], Period]:
        """Load the scenario (seed, split); return it and its first period (the reset frame).

        Everything received before the reset is forgotten, decisions included (the reset
        stops the motors: no earlier command acts in the new episode).
        """
        self.client.set_parameters(seed=seed, split=split)
        self.drain()
        scenario = self.client.request_reset()
        stamp = int(scenario['stamp_ns'])
        if not self.spin_until(lambda: stamp in self.ticks and stamp in self.images, timeout):
            raise EvaluationError(f'no reset frame from nav_sim in {self.client.where} within '
                                  f'{timeout} s')
        first = self.period(stamp)
        self.forget(before_ns=stamp, published_before=first.tick.published_ns)
        return scenario, first

    def period(self, stamp: int) -> Period:
        """Return the period stamped ``stamp`` (its tick and image must have arrived)."""
        image, published = self.images[stamp]
        return Period(self.ticks[stamp], image, published)

    def next_period(self, after_ns: int, timeout: float) -> Period:
        """Return the first period stamped after ``after_ns`` whose image has arrived too.

        A period whose image was lost is skipped once a later one is complete (per topic,
        DDS delivers in order: a later image means the earlier one will not come).
        """
        def ready() -> int | None:
            complete = [s for s in self.ticks if s > after_ns and s in self.images]
            return min(complete) if complete else None

        if not self.spin_until(lambda: ready() is not None, timeout):
            raise EvaluationError(f'the realtime sim in {self.client.where} published no '
                                  f'period within {timeout} s')
        self.drain()  # decisions published before this tick may still wait in the queue
        stamp = ready()
        assert stamp is not None
        return self.period(stamp)

    def forget(self, before_ns: int, published_before: int) -> None:
        """Drop periods stamped before ``before_ns`` and decisions published before a time."""
        self.ticks = {s: t for s, t in self.ticks.items() if s >= before_ns}
        self.images = {s: i for s, i in self.images.items() if s >= before_ns}
        self.decisions = [d for d in self.decisions if d.published_ns >= published_before]

    def stop(self) -> None:
        """Stop the motors (between episodes: the policy node goes on deciding)."""
        self.client.stop()

    def close(self) -> None:
        """Destroy the client node and its context."""
        self.client.close()
