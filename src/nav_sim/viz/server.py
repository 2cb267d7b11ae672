"""The live view: a Foxglove WebSocket server inside our own process (Foxglove SDK, no rclpy).

``LiveView(port, topics)`` starts ``foxglove.start_server`` and advertises one channel per topic
of :mod:`nav_sim.viz.topics`, each with its ROS 2 type as a ``ros2msg`` schema and ``cdr``
message encoding, so Foxglove decodes them exactly as it decodes the recorded MCAP bags.

Cost: nothing is built or serialized for a channel no viewer subscribes to (``has_sinks``), so
with nobody connected a log call is one cheap check.  Messages are passed as zero-argument
factories for that reason.  The server sends in its own (Rust) threads.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from typing import Any

from nav_sim.errors import ConfigError
from nav_sim.viz import topics as live_topics

_log = logging.getLogger(__name__)

MAX_PATH_POINTS = 5000  # the robot marker's path keeps the newest this many poses
#: the most messages per second (wall clock) a topic sends: a bare env runs a few hundred steps
#: per second, a viewer cannot show more, and each message costs about 0.1 ms of CPU in the
#: server's sending thread (``benchmarks/bench_live.py``).  A changed scene waits for its turn;
#: the step that ends an episode always goes; events and /diagnostics are never dropped.  In
#: slow runs (evaluation, a paced demo) nothing is dropped; every step is in the bags anyway.
MAX_RATE_HZ = {live_topics.CAMERA_TOPIC: 15.0, live_topics.OBSERVATION_TOPIC: 15.0,
               live_topics.ROBOT_TOPIC: 15.0, live_topics.SCENE_TOPIC: 15.0,
               live_topics.STEP_TOPIC: 30.0, live_topics.TRAINING_TOPIC: 10.0}
HOST = '127.0.0.1'    # local viewers only; Foxglove opens ws://localhost:PORT


class LiveViewError(ConfigError):
    """The live view's server could not start (e.g. the port is taken)."""


class _Listener:
    """Notes which topics a viewer has just subscribed to (to re-send the static scene)."""

    def __init__(self) -> None:
        self.new_subscriptions: set[str] = set()

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.new_subscriptions.add(channel.topic)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self.new_subscriptions.discard(channel.topic)


class LiveView:
    """A Foxglove server advertising ``topics`` (names of :data:`live_topics.TOPIC_TYPES`)."""

    def __init__(self, port: int, topics: Iterable[str], name: str = 'visnav',
                 host: str = HOST) -> None:
        """Start the server on ``host:port`` and advertise one channel per topic."""
        import foxglove  # only when the live view is on: no import cost otherwise

        self._context = foxglove.Context()
        self._listener = _Listener()
        try:
            self.server = foxglove.start_server(name=name, host=host, port=port,
                                                context=self._context,
                                                server_listener=self._listener)
        except Exception as exc:  # the SDK raises a plain RuntimeError
            raise LiveViewError(f'cannot start the live view on {host}:{port} ({exc}); choose '
                                'another port (--live PORT, or live_port:=PORT)') from None
        self.port = self.server.port
        self.url = f'ws://localhost:{self.port}'
        self._channels = {}
        self._min_interval = {t: 1.0 / hz for t, hz in MAX_RATE_HZ.items()}
        self._last_sent = dict.fromkeys(MAX_RATE_HZ, -1e9)
        for topic in topics:
            msgtype = live_topics.TOPIC_TYPES[topic]
            schema = foxglove.Schema(name=msgtype, encoding='ros2msg',
                                     data=live_topics.schema_text(msgtype).encode())
            self._channels[topic] = foxglove.Channel(topic, schema=schema,
                                                     message_encoding='cdr',
                                                     context=self._context)
        _log.info('live view on %s (Foxglove: Open connection -> Foxglove WebSocket)', self.url)

    @property
    def topics(self) -> tuple[str, ...]:
        """The advertised topics."""
        return tuple(self._channels)

    def wanted(self, topic: str) -> bool:
        """Return True if a viewer subscribes to ``topic``."""
        channel = self._channels.get(topic)
        return channel is not None and channel.has_sinks()

    def newly_subscribed(self, topic: str) -> bool:
        """Return True once after a viewer subscribed to ``topic`` (to re-send what it missed)."""
        if topic in self._listener.new_subscriptions:
            self._listener.new_subscriptions.discard(topic)
            return True
        return False

    def log(self, topic: str, message: Callable[[], Any], stamp_ns: int,
            force: bool = False) -> bool:
        """Serialize and send ``message()`` on ``topic`` if a viewer subscribes; True if sent.

        A topic of ``MAX_RATE_HZ`` goes at most that often unless ``force``.
        """
        channel = self._channels.get(topic)
        if channel is None or not channel.has_sinks():
            return False
        if topic in self._last_sent:
            now = time.monotonic()
            if not force and now - self._last_sent[topic] < self._min_interval[topic]:
                return False
            self._last_sent[topic] = now
        channel.log(live_topics.to_cdr(message(), live_topics.TOPIC_TYPES[topic]),
                    log_time=stamp_ns)
        return True

    def log_cdr(self, topic: str, data: Callable[[], bytes], stamp_ns: int) -> bool:
        """Send CDR bytes made by ``data()`` (e.g. an rclpy message serialized) if wanted."""
        channel = self._channels.get(topic)
        if channel is None or not channel.has_sinks():
            return False
        channel.log(bytes(data()), log_time=stamp_ns)
        return True

    def close(self) -> None:
        """Stop the server (viewers see the connection close)."""
        server, self.server = self.server, None
        if server is not None:
            server.stop()


class EpisodeScene:
    """The 3D scene of the current episode, kept for a live view and for bag writers.

    ``reset`` takes the episode description (``Scenario.to_dict()``) and the start pose; ``step``
    appends a pose to the path.  ``scene`` and ``robot`` build the two MarkerArrays.
    """

    def __init__(self, arena: live_topics.ArenaScene) -> None:
        """Draw in ``arena``; no episode yet."""
        self.arena = arena
        self.scenario: dict[str, Any] | None = None
        self.path: list[tuple[float, float]] = []
        self.pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._scene_pending = False  # a new episode's scene not yet sent

    def reset(self, scenario: dict[str, Any], pose: tuple[float, float, float]) -> None:
        """Start a new episode's path at ``pose``."""
        self.scenario = scenario
        self.pose = tuple(float(v) for v in pose)  # type: ignore[assignment]
        self.path = [(self.pose[0], self.pose[1])]

    def step(self, pose: tuple[float, float, float]) -> None:
        """Move the robot to ``pose`` and extend the path."""
        moved = tuple(float(v) for v in pose)
        if self.path and moved[:2] == self.path[-1]:
            self.pose = moved  # type: ignore[assignment]
            return  # a stopped robot (realtime mode after the episode's end) adds no points
        self.pose = moved  # type: ignore[assignment]
        self.path.append((moved[0], moved[1]))
        if len(self.path) > MAX_PATH_POINTS:  # a realtime sim driven for hours
            del self.path[:len(self.path) - MAX_PATH_POINTS]

    def scene(self, stamp_ns: int) -> Any:
        """Build the static world MarkerArray of the episode."""
        assert self.scenario is not None
        return live_topics.scene_markers(self.arena, self.scenario, stamp_ns)

    def robot(self, stamp_ns: int) -> Any:
        """Build the robot and path MarkerArray."""
        return live_topics.robot_markers(self.arena, self.pose, self.path, stamp_ns)

    def log(self, live: LiveView, stamp_ns: int, new_episode: bool) -> None:
        """Send the robot and, after a new episode or to a new viewer, the scene to ``live``.

        A scene the rate limit holds back goes with a later frame (the newest scene).
        """
        if self.scenario is None:
            return
        if new_episode | live.newly_subscribed(live_topics.SCENE_TOPIC):
            self._scene_pending = True
        if self._scene_pending and live.log(live_topics.SCENE_TOPIC,
                                            lambda: self.scene(stamp_ns), stamp_ns):
            self._scene_pending = False
        live.log(live_topics.ROBOT_TOPIC, lambda: self.robot(stamp_ns), stamp_ns)
