"""Record the nav_sim topics of one namespace into a rosbag2 bag (MCAP storage) with ``rosbags``.

:class:`BagRecorder` subscribes (``raw=True``) to what ``nav_sim/sim_node`` publishes and what
drives it, and writes the CDR bytes unchanged, each under its fully resolved topic name:

    <ns>/camera/image_raw     sensor_msgs/msg/Image
    <ns>/camera/camera_info   sensor_msgs/msg/CameraInfo
    <ns>/odom                 nav_msgs/msg/Odometry
    <ns>/goal_pose            geometry_msgs/msg/PoseStamped (transient local)
    <ns>/episode_event        diagnostic_msgs/msg/DiagnosticArray
    <ns>/cmd_vel              geometry_msgs/msg/Twist
    /clock                    rosgraph_msgs/msg/Clock
    /visnav/episode           std_msgs/msg/String (only written by :meth:`BagRecorder.annotate`)

and, with ``topics=WITH_POLICY`` (the closed-loop evaluation, ``nav-eval-record``), what the
policy node (``ros2 run nav_gym policy``) publishes besides ``cmd_vel``:

    <ns>/policy/decision      sensor_msgs/msg/JointState (stamped with the decided image's stamp)

The bag is rosbag2 version 9 (what Jazzy writes); ``metadata.yaml`` appears when the recorder is
closed.  Bag timestamps are sim time, so a recording of a seeded run is reproducible: the header
stamp (the Clock's value on ``/clock``) of every stamped message; for ``cmd_vel``, which has no
header, and for annotations, the newest sim stamp seen so far (in lockstep that is normally the
stamp of the observation the command answers).  Unstamped messages that arrive before any sim
stamp wait for the first one; if none comes within ``HOLD_S``, they (and later unstamped ones)
get wall-clock time.  Timestamps never decrease within a topic, so record one sim run per bag:
a restarted sim starts its clock again at zero.

Connecting takes a moment: :meth:`BagRecorder.wait_for_publishers` says when the recorder has
matched the sim's publishers, but the sim can match the recorder's subscriptions a few hundred
milliseconds later, and what it publishes before then never reaches the bag.  Before a run that
must be complete, reset and step until :meth:`BagRecorder.wait_for` sees a whole control period
(``topics=PERIOD_TOPICS``).

Reading a bag back (episodes, events, messages) is :mod:`nav_eval.recording.bags`, which needs
no rclpy.
"""

from __future__ import annotations

import json
import logging
import shutil
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer, WriterError
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState

from nav_eval.errors import RecordingError
from nav_eval.recording.bags import (
    BAG_VERSION,
    EPISODE_TOPIC,
    IMAGE_TOPIC,
    SIM_TOPICS,
    STRING_TYPE,
    TYPESTORE,
    cdr_stamp_ns,
)
from nav_sim import interface, qos

_log = logging.getLogger(__name__)

QUEUE_DEPTH = 50           # subscriber queue: a briefly slow recorder loses nothing
SPIN_TIMEOUT_S = 0.1       # how soon the recording thread notices close()
DRAIN_S = 0.5              # at close, write what already arrived for at most this long
HOLD_S = 10.0              # unstamped messages wait this long for a first sim stamp ...
HOLD_MAX = 1000            # ... or until this many are waiting
POLL_S = 0.02
_NEVER = 2**63            # the start stamp of a paused recorder


@dataclass(frozen=True)
class RecordedTopic:
    """One topic the recorder subscribes to."""

    name: str             # relative to the namespace (absolute for /clock)
    msgtype: str          # ROS 2 type name, as stored in the bag
    msg_class: type       # rclpy message class to subscribe with
    profile: QoSProfile   # what the publisher offers (nav_sim.qos); the recorder queues deeper
    stamped: bool         # starts with a builtin_interfaces/Time (header stamp, Clock value)


TOPICS = (
    RecordedTopic(IMAGE_TOPIC, 'sensor_msgs/msg/Image', Image, qos.OBSERVATION, True),
    RecordedTopic(interface.CAMERA_INFO_TOPIC, 'sensor_msgs/msg/CameraInfo', CameraInfo,
                  qos.OBSERVATION, True),
    RecordedTopic(interface.ODOM_TOPIC, 'nav_msgs/msg/Odometry', Odometry, qos.OBSERVATION,
                  True),
    RecordedTopic(interface.GOAL_TOPIC, 'geometry_msgs/msg/PoseStamped', PoseStamped,
                  qos.LATCHED, True),
    RecordedTopic(interface.EVENT_TOPIC, 'diagnostic_msgs/msg/DiagnosticArray', DiagnosticArray,
                  qos.OBSERVATION, True),
    RecordedTopic(interface.CMD_VEL_TOPIC, 'geometry_msgs/msg/Twist', Twist, qos.CONTROL, False),
    RecordedTopic(interface.CLOCK_TOPIC, 'rosgraph_msgs/msg/Clock', Clock, qos.CLOCK, True),
)
#: the sim's topics and the policy node's decisions
WITH_POLICY = (*TOPICS, RecordedTopic(interface.DECISION_TOPIC, 'sensor_msgs/msg/JointState',
                                      JointState, qos.DECISIONS, True))


def bag_qos(profile: QoSProfile) -> Qos:
    """Return the rosbags form of an rclpy QoS profile (durations left at the default)."""
    default = QosTime(0, 0)
    return Qos(QosHistory(profile.history.value), profile.depth,
               QosReliability(profile.reliability.value), QosDurability(profile.durability.value),
               default, default, QosLiveliness(profile.liveliness.value), default, False)


def _json_value(value: Any) -> Any:
    """Numpy scalars and arrays as plain Python values, for ``json.dumps``."""
    for method in ('tolist', 'item'):
        if hasattr(value, method):
            return getattr(value, method)()
    raise TypeError(f'{type(value).__name__} is not JSON serializable')


class BagRecorder:
    """Record the nav_sim topics of ``namespace`` into a new MCAP bag at ``path``.

    Runs its own rclpy context and node, spun by a SingleThreadedExecutor in a daemon thread;
    :meth:`close` (or leaving the ``with`` block) finishes the bag.
    """

    def __init__(self, path: str | Path, namespace: str = '', *,
                 node_name: str = 'visnav_recorder', queue_depth: int = QUEUE_DEPTH,
                 paused: bool = False, root_names: bool = False,
                 topics: tuple[RecordedTopic, ...] = TOPICS) -> None:
        """Create the bag at ``path`` (which must not exist) and start recording ``topics``.

        ``paused`` notes messages without writing them until :meth:`start`; ``root_names``
        writes the graph topics under root-namespace names instead of their resolved ones.
        """
        self.topics = topics
        self.path = Path(path)
        # root_names: write the graph topics as if the sim ran in the root namespace
        # (camera/image_raw -> /camera/image_raw), the names the live view and the shipped
        # Foxglove layout use; otherwise under their fully resolved names
        self.root_names = root_names
        self._extra: dict[str, Connection] = {}  # topics given to write(), by name
        self.namespace = '/' + namespace.strip('/') if namespace.strip('/') else ''
        if self.path.exists():
            raise RecordingError(f'{self.path} exists already; rosbag2 bags are never '
                                 'overwritten: choose a new output directory or remove it')
        self._cond = threading.Condition(threading.Lock())
        self._counts: dict[str, int] = {}
        self._last_ns: dict[int, int] = {}
        self._sim_ns: int | None = None
        self._ids: dict[str, int] = {}          # topic name as in TOPICS -> connection id
        self._stamp_ns: dict[int, int] = {}     # connection id -> newest header stamp written
        self._received = 0
        self._held: list[tuple[Connection, bytes, int]] = []  # unstamped, before any sim stamp
        self._wall_clock = False  # no sim stamp in time: unstamped messages get wall-clock time
        # paused: messages stamped before this are only noted for wait_for (see start())
        self._start_ns = _NEVER if paused else 0
        self._failure: BaseException | None = None
        self._closed = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._context: rclpy.Context | None = None
        self._node: Node | None = None
        self._executor: SingleThreadedExecutor | None = None
        self._subscriptions: dict[str, Subscription] = {}
        self._writer: Writer | None = None
        try:
            self._writer = Writer(self.path, version=BAG_VERSION,
                                  storage_plugin=StoragePlugin.MCAP)
            # zstd-compressed MCAP chunks (what `ros2 bag record --storage-preset-profile
            # zstd_fast` writes): camera images shrink ~19x, every MCAP reader reads them
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            self._writer.open()
        except (WriterError, OSError) as exc:
            raise RecordingError(f'cannot create the bag {self.path}: {exc}') from exc
        try:
            self._start_node(node_name, queue_depth)
        except BaseException:
            self._abandon()
            raise

    # --- set-up ---------------------------------------------------------------------------
    def _start_node(self, node_name: str, queue_depth: int) -> None:
        self._context = rclpy.Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        node = self._node = rclpy.create_node(node_name, namespace=self.namespace or '/',
                                              context=self._context,
                                              start_parameter_services=False, enable_rosout=False)
        for topic in self.topics:
            name = ('/' + topic.name.lstrip('/') if self.root_names
                    else node.resolve_topic_name(topic.name))
            connection = self._add_connection(name, topic.msgtype, [bag_qos(topic.profile)])
            profile = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=queue_depth,
                                 reliability=topic.profile.reliability,
                                 durability=topic.profile.durability)
            self._subscriptions[topic.name] = node.create_subscription(
                topic.msg_class, topic.name, partial(self._on_raw, connection, topic.stamped),
                profile, raw=True)
            self._ids[topic.name] = connection.id
        self._episode_connection = self._add_connection(EPISODE_TOPIC, STRING_TYPE, [])
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(node)
        self._thread = threading.Thread(target=self._spin, name='bag_recorder', daemon=True)
        self._thread.start()

    def _add_connection(self, topic: str, msgtype: str, profiles: list[Qos]) -> Connection:
        assert self._writer is not None
        connection = self._writer.add_connection(topic, msgtype, typestore=TYPESTORE,
                                                 offered_qos_profiles=profiles)
        self._counts[topic] = 0
        return connection

    def _abandon(self) -> None:
        """Undo a failed construction: stop ROS and remove the bag directory it created."""
        self._stop_node()
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.abort()
        shutil.rmtree(self.path, ignore_errors=True)
        self._closed = True

    # --- the recording thread -------------------------------------------------------------
    def _on_raw(self, connection: Connection, stamped: bool, data: bytes) -> None:
        self._received += 1
        self._write(connection, data, cdr_stamp_ns(data) if stamped else None)

    def _spin(self) -> None:
        try:
            while not self._stop.is_set():
                self._executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
            deadline = time.monotonic() + DRAIN_S
            while time.monotonic() < deadline:
                before = self._received
                self._executor.spin_once(timeout_sec=0.0)
                if self._received == before:
                    break
        except Exception as exc:  # a failed write ends the recording; close() reports it
            _log.exception('bag recording of %s failed', self.path)
            with self._cond:
                self._failure = exc
                self._cond.notify_all()

    def _write(self, connection: Connection, data: bytes | memoryview,
               stamp_ns: int | None) -> None:
        """Write one message at its sim stamp, or the newest sim stamp if it has none.

        Unstamped messages that come before any sim stamp wait for the first one (for at most
        ``HOLD_S`` or ``HOLD_MAX`` messages; after that, unstamped ones get wall-clock time).
        """
        with self._cond:
            if self._writer is None:
                return
            if self._start_ns and self._skip(connection, stamp_ns):
                return
            if stamp_ns is None:
                if self._sim_ns is None and not self._wall_clock:
                    self._hold(connection, data)
                    return
                self._put(connection, time.time_ns() if self._wall_clock else self._sim_ns,
                          data)
                return
            if self._sim_ns is None:
                self._sim_ns = stamp_ns
                self._release_held(stamp_ns)
            self._sim_ns = max(self._sim_ns, stamp_ns)
            self._put(connection, stamp_ns, data)
            self._stamp_ns[connection.id] = max(stamp_ns, self._stamp_ns.get(connection.id, 0))
            self._cond.notify_all()

    def _skip(self, connection: Connection, stamp_ns: int | None) -> bool:
        """Note (for wait_for) but do not write what comes before the start (see start())."""
        if stamp_ns is None:
            return self._sim_ns is None or self._sim_ns < self._start_ns
        if stamp_ns >= self._start_ns:
            return False
        self._stamp_ns[connection.id] = max(stamp_ns, self._stamp_ns.get(connection.id, 0))
        self._cond.notify_all()
        return True

    def _put(self, connection: Connection, when: int, data: bytes | memoryview) -> None:
        assert self._writer is not None
        when = max(when, self._last_ns.get(connection.id, 0))  # monotonic per topic
        self._writer.write(connection, when, data)
        self._last_ns[connection.id] = when
        self._counts[connection.topic] += 1

    def _hold(self, connection: Connection, data: bytes | memoryview) -> None:
        self._held.append((connection, bytes(data), time.time_ns()))
        if (len(self._held) >= HOLD_MAX
                or self._held[-1][2] - self._held[0][2] > HOLD_S * 1_000_000_000):
            self._wall_clock = True
            self._release_held(None)

    def _release_held(self, stamp_ns: int | None) -> None:
        """Write the held messages at ``stamp_ns``, or at their arrival times if None."""
        for connection, data, wall_ns in self._held:
            self._put(connection, wall_ns if stamp_ns is None else stamp_ns, data)
        self._held.clear()

    # --- public API -----------------------------------------------------------------------
    @property
    def received(self) -> int:
        """Return how many messages the recorder has taken off the network (written or not)."""
        return self._received

    @property
    def counts(self) -> dict[str, int]:
        """Messages written so far per resolved topic name (annotations included)."""
        with self._cond:
            return dict(self._counts)

    def wait_for_publishers(self, timeout: float, topics: Iterable[str] = SIM_TOPICS) -> bool:
        """Block until each of ``topics`` (names as in :data:`TOPICS`) has a matched publisher.

        Call it before driving the sim, so the first messages are not sent before the recorder
        is connected.  Returns False after ``timeout`` seconds.
        """
        subscriptions = [self._subscriptions[name] for name in self._known(topics)]
        deadline = time.monotonic() + timeout
        while not all(sub.get_publisher_count() > 0 for sub in subscriptions):
            if time.monotonic() >= deadline:
                return False
            time.sleep(POLL_S)
        return True

    def wait_for(self, stamp_ns: int, timeout: float,
                 topics: Iterable[str] = (IMAGE_TOPIC,)) -> bool:
        """Block until an image (each of ``topics``) stamped ``stamp_ns`` or later is written.

        Returns False after ``timeout`` seconds.  Lockstep callers wait for each step's frame so
        the sim's depth-1 publishers never outrun the recorder.  Waiting for a reset frame on
        every stamped topic confirms that the sim, too, has matched the recorder: it can do so
        a few hundred milliseconds after :meth:`wait_for_publishers` returns, and what it
        publishes before then never reaches the bag.
        """
        ids = [self._ids[name] for name in self._known(topics)]
        if self._ids[interface.CMD_VEL_TOPIC] in ids:
            raise ValueError('cmd_vel has no stamp to wait for')

        def arrived() -> bool:
            return all(self._stamp_ns.get(i, -1) >= stamp_ns for i in ids)

        with self._cond:
            self._cond.wait_for(lambda: arrived() or self._failure is not None
                                or self._writer is None, timeout)
            if self._failure is not None:
                raise RecordingError(f'recording into {self.path} failed: {self._failure}')
            return arrived()

    def start(self, from_ns: int) -> None:
        """Write messages stamped ``from_ns`` or later (a recorder made with ``paused=True``).

        Before it, a paused recorder only notes what arrives, so :meth:`wait_for` can confirm
        on warm-up periods that the sim has matched the recorder without them entering the bag.
        Unstamped messages are written once a message stamped ``from_ns`` or later arrived.
        """
        with self._cond:
            self._start_ns = from_ns

    def annotate(self, info: Mapping[str, Any]) -> None:
        """Write ``json.dumps(info)`` as a std_msgs/String on ``/visnav/episode``.

        It goes at the newest sim stamp seen, so an annotation made at an episode's end
        carries the stamp of the episode's last frame.
        """
        text = json.dumps(dict(info), default=_json_value)
        data = TYPESTORE.serialize_cdr(TYPESTORE.types[STRING_TYPE](data=text), STRING_TYPE)
        with self._cond:
            if self._writer is None:
                raise RecordingError(f'cannot annotate {self.path}: the recorder is closed')
        self._write(self._episode_connection, data, None)

    def write(self, topic: str, msgtype: str, data: bytes, stamp_ns: int) -> None:
        """Write a message that does not come from the graph.

        The message is CDR ``data`` of ``msgtype`` (a type of
        :data:`nav_eval.recording.bags.TYPESTORE`), written on ``topic`` at the sim stamp
        ``stamp_ns``.

        The evaluation writes the live view's scene topics this way
        (:mod:`nav_eval.recording.scene`).
        """
        with self._cond:
            if self._writer is None:
                raise RecordingError(f'cannot write to {self.path}: the recorder is closed')
            connection = self._extra.get(topic)
            if connection is None:
                connection = self._extra[topic] = self._add_connection(topic, msgtype, [])
        self._write(connection, data, stamp_ns)

    def _known(self, topics: Iterable[str]) -> tuple[str, ...]:
        topics = tuple(topics)
        unknown = sorted(set(topics) - set(self._ids))
        if unknown:
            raise ValueError(f'not recorded: {unknown}; choose from {list(self._ids)}')
        return topics

    def _stop_node(self) -> None:
        """Stop and join the thread, then destroy the node and the context (in that order)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self._executor is not None:
            self._executor.shutdown(timeout_sec=1.0)
        if self._node is not None:
            self._node.destroy_node()
        if self._context is not None:
            self._context.try_shutdown()

    def close(self) -> None:
        """Finish the recording and write ``metadata.yaml``; safe to call more than once."""
        if self._closed:
            return
        self._closed = True
        self._stop_node()
        with self._cond:
            self._release_held(None)
            writer, self._writer = self._writer, None
            self._cond.notify_all()
        if writer is not None:
            writer.close()
        if self._failure is not None:
            raise RecordingError(f'recording into {self.path} failed: {self._failure}; '
                                 'the bag holds what was written before') from self._failure

    def __enter__(self) -> BagRecorder:
        """Return the recorder itself."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Finish the recording (see :meth:`close`)."""
        self.close()
