"""Record the nav_sim topics of one namespace into a rosbag2 bag (MCAP storage) with ``rosbags``.

:class:`BagRecorder` subscribes (``raw=True``) to what ``nav_sim/sim_node`` publishes and what
drives it, and writes the CDR bytes unchanged, each under its fully resolved topic name:

    <ns>/camera/image_raw     sensor_msgs/msg/Image
    <ns>/camera/camera_info   sensor_msgs/msg/CameraInfo
    <ns>/odom                 nav_msgs/msg/Odometry
    <ns>/goal_pose            geometry_msgs/msg/PoseStamped (transient local)
    <ns>/episode_event        diagnostic_msgs/msg/DiagnosticArray
    <ns>/cmd_vel              geometry_msgs/msg/Twist (TwistStamped with cmd_vel_stamped)
    /clock                    rosgraph_msgs/msg/Clock
    /visnav/episode           std_msgs/msg/String (only written by :meth:`BagRecorder.annotate`)

and, with ``topics=WITH_POLICY`` (the closed-loop evaluation, ``nav-eval-record``), what the
policy node (``ros2 run nav_gym policy``) publishes besides ``cmd_vel``:

    <ns>/policy/decision      sensor_msgs/msg/JointState (stamped with the decided image's stamp)

The bag is rosbag2 version 9 (what Jazzy writes); ``metadata.yaml`` appears when the recorder is
closed.  Bag timestamps are sim time (:class:`nav_eval.recording.timestamps.StampPolicy`), so a
recording of a seeded run is reproducible; record one sim run per bag: a restarted sim starts
its clock again at zero.  The topics are :mod:`nav_eval.recording.topics`.

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
from functools import partial
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.subscription import Subscription
from rosbags.interfaces import (
    Connection,
    Qos,
)
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer, WriterError

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
from nav_eval.recording.timestamps import Placed, StampPolicy
from nav_eval.recording.topics import TOPICS, RecordedTopic, bag_qos, with_cmd_vel
from nav_sim import interface
from nav_sim.ros.bare import own_node

_log = logging.getLogger(__name__)

QUEUE_DEPTH = 50           # subscriber queue: a briefly slow recorder loses nothing
SPIN_TIMEOUT_S = 0.1       # how soon the recording thread notices close()
DRAIN_S = 0.5              # at close, write what already arrived for at most this long
POLL_S = 0.02


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
                 topics: tuple[RecordedTopic, ...] = TOPICS,
                 cmd_vel_stamped: bool = False) -> None:
        """Create the bag at ``path`` (which must not exist) and start recording ``topics``.

        ``paused`` notes messages without writing them until :meth:`start`; ``root_names``
        writes the graph topics under root-namespace names instead of their resolved ones;
        ``cmd_vel_stamped`` records ``cmd_vel`` as TwistStamped (the sim's setting).
        """
        self.topics = with_cmd_vel(topics, cmd_vel_stamped)
        self.path = Path(path)
        # root_names: write the graph topics as if the sim ran in the root namespace
        # (camera/image_raw -> /camera/image_raw), the names the live view and the shipped
        # Foxglove layout use; otherwise under their fully resolved names
        self.root_names = root_names
        self._extra: dict[str, Connection] = {}  # topics given to write(), by name
        try:  # the graph's one namespace rule; '' records the root, as '/' does
            self.namespace = interface.absolute_namespace(namespace) or '/'
        except ValueError as exc:
            raise RecordingError(str(exc)) from None
        if self.path.exists():
            raise RecordingError(f'{self.path} exists already; rosbag2 bags are never '
                                 'overwritten: choose a new output directory or remove it')
        self._cond = threading.Condition(threading.Lock())
        self._counts: dict[str, int] = {}
        self._ids: dict[str, int] = {}          # topic name as in TOPICS -> connection id
        self._connections: dict[int, Connection] = {}  # connection id -> connection
        self._received = 0
        # paused: messages stamped before the start are only noted for wait_for (see start())
        self._stamps = StampPolicy(paused)
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
        self._context, node = own_node(node_name, self.namespace)
        self._node = node
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
        self._connections[connection.id] = connection
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
        """Write one message when the timestamp policy says (:mod:`.timestamps`)."""
        with self._cond:
            if self._writer is None:
                return
            # an unstamped message may be held: keep a copy of a reused receive buffer
            placed = self._stamps.place(connection.id, bytes(data) if stamp_ns is None
                                        else data, stamp_ns)
            self._put(placed)
            if stamp_ns is not None:
                self._cond.notify_all()

    def _put(self, placed: list[Placed]) -> None:
        assert self._writer is not None
        for key, when, data in placed:
            connection = self._connections[key]
            self._writer.write(connection, when, data)
            self._counts[connection.topic] += 1

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
            return all(self._stamps.newest(i) >= stamp_ns for i in ids)

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
            self._stamps.start(from_ns)

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
            if self._writer is not None:
                self._put(self._stamps.flush())
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
