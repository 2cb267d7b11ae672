"""Read the bags that :mod:`nav_eval.recording.recorder` writes (``rosbags`` only, no rclpy).

The bag layout: rosbag2 version 9 (what Jazzy writes), MCAP storage, sim-time timestamps, one
topic per fully resolved name.

Finding episodes in a bag:

* ``/visnav/episode``: one JSON annotation per finished episode (set, policy, checkpoint, seed,
  split, outcome, length, return, ...), written by the evaluation at the stamp of the episode's
  last frame; :func:`episodes_in_bag` returns them in order.  The always-absolute topic name keeps
  them in one place whatever namespace the sim ran in.
* ``<ns>/episode_event``: one DiagnosticArray per control period (status ``nav_sim/episode``, see
  :mod:`nav_sim.ros.messages`).  Its message is ``reset`` on an episode's first frame (key/values
  ``episode``, ``seed``, ``split``), ``goal`` or ``collision`` on a terminal frame (``done`` is
  True) and ``none`` otherwise.  Every message of one control period shares the stamp, so the
  messages from one ``reset`` stamp up to (not including) the next belong to one episode;
  :func:`episode_events` returns the parsed events.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import Reader

from nav_sim import interface
from nav_sim.ros import messages as ros_msgs
from nav_sim.viz import topics as live_topics

BAG_VERSION = 9            # the rosbag2 metadata version ROS 2 Jazzy writes
IMAGE_TOPIC = interface.IMAGE_TOPIC
EPISODE_TOPIC = '/visnav/episode'
STRING_TYPE = 'std_msgs/msg/String'
#: what nav_sim publishes every control period (and ``/clock`` with ``publish_clock``)
PERIOD_TOPICS = (IMAGE_TOPIC, interface.CAMERA_INFO_TOPIC, interface.ODOM_TOPIC,
                 interface.EVENT_TOPIC)
#: topics every nav_sim node publishes
SIM_TOPICS = (*PERIOD_TOPICS, interface.GOAL_TOPIC)

#: ROS 2 Jazzy types plus the live view's visnav_msgs types (nav_sim.viz.topics)
TYPESTORE = live_topics.TYPESTORE  # Jazzy's types and visnav's own (one typestore)


def cdr_stamp_ns(data: bytes | memoryview) -> int | None:
    """Return the builtin_interfaces/Time a CDR message starts with (header stamp, Clock), in ns.

    Reads 8 bytes after the 4-byte encapsulation header instead of deserializing the message;
    None if ``data`` is too short to hold one.
    """
    if len(data) < 12:
        return None
    sec, nanosec = struct.unpack_from('<iI' if data[1] & 1 else '>iI', data, 4)
    return sec * 1_000_000_000 + nanosec


def read_bag(path: str | Path, topics: Iterable[str] | None = None
             ) -> dict[str, list[tuple[int, Any]]]:
    """Every message of a bag (or of ``topics``) as (timestamp_ns, message) lists per topic.

    Messages are rosbags dataclasses with the field names of the ROS 2 messages.
    """
    wanted = None if topics is None else set(topics)
    with Reader(path) as reader:
        connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
        out: dict[str, list[tuple[int, Any]]] = {c.topic: [] for c in connections}
        for connection, timestamp, raw in (reader.messages(connections=connections)
                                           if connections else ()):
            out[connection.topic].append(
                (timestamp, TYPESTORE.deserialize_cdr(raw, connection.msgtype)))
    return out


def episodes_in_bag(path: str | Path) -> list[dict[str, Any]]:
    """Return the ``/visnav/episode`` annotations of a bag, parsed from JSON, in order."""
    messages = read_bag(path, [EPISODE_TOPIC]).get(EPISODE_TOPIC, [])
    return [json.loads(msg.data) for _, msg in messages]


def episode_events(path: str | Path) -> list[tuple[int, dict[str, Any]]]:
    """(timestamp_ns, event dict) of every ``*/episode_event`` message, in time order.

    The dicts are :func:`nav_sim.ros.messages.parse_event`'s: ``event`` (``reset``, ``none``,
    ``goal``, ``collision``) plus ``topic`` and the counters (``episode``, ``seed``, ...).
    """
    with Reader(path) as reader:
        topics = [c.topic for c in reader.connections
                  if c.topic.endswith(f'/{interface.EVENT_TOPIC}')]
    events = []
    for topic, messages in read_bag(path, topics).items():
        for timestamp, msg in messages:
            event = ros_msgs.parse_event(msg)
            if event is not None:
                events.append((timestamp, {**event, 'topic': topic}))
    events.sort(key=lambda item: item[0])
    return events
