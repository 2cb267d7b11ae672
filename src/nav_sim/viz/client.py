"""A headless Foxglove WebSocket client of the live view (tests, benchmark, scripted checks).

Speaks the Foxglove WebSocket protocol (subprotocol ``foxglove.sdk.v1``) with ``websockets``:
reads the server's ``advertise``, subscribes to channels by topic and decodes the binary
``messageData`` frames (opcode 1: subscription id, log time, CDR payload) with the rosbags
typestore of :mod:`nav_sim.viz.topics`.
"""

from __future__ import annotations

import json
import struct
import time
from dataclasses import dataclass
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from nav_sim.viz import topics as live_topics
from nav_sim.viz.options import DEFAULT_PORT

SUBPROTOCOL = 'foxglove.sdk.v1'
MESSAGE_DATA = 1


@dataclass(frozen=True)
class LiveMessage:
    """One message received from the live view."""

    topic: str
    log_time_ns: int
    data: bytes

    def decode(self) -> Any:
        """Deserialize the CDR payload with the topic's ROS 2 type."""
        return live_topics.from_cdr(self.data, live_topics.TOPIC_TYPES[self.topic])


class LiveClient:
    """Connect to ``ws://host:port``; :attr:`channels` maps topic -> advertised channel."""

    def __init__(self, port: int, host: str = '127.0.0.1', timeout: float = 10.0) -> None:
        """Connect and wait (up to ``timeout`` s) for the server's channel advertisement."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.ws = connect(f'ws://{host}:{port}', subprotocols=[SUBPROTOCOL],
                                  open_timeout=timeout, max_size=None).__enter__()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        self.channels: dict[str, dict[str, Any]] = {}
        self._topics_by_subscription: dict[int, str] = {}
        self.pending: list[LiveMessage] = []
        try:
            while not self.channels:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f'no channels advertised on port {port} within '
                                       f'{timeout} s')
                self._receive(left)
        except BaseException:
            self.ws.close()  # nothing to watch: do not leak the connection
            raise

    def subscribe(self, topics: list[str] | tuple[str, ...]) -> None:
        """Subscribe to the channels of ``topics`` (KeyError if one is not advertised)."""
        subscriptions = []
        for topic in topics:
            sub_id = len(self._topics_by_subscription) + 1
            self._topics_by_subscription[sub_id] = topic
            subscriptions.append({'id': sub_id, 'channelId': self.channels[topic]['id']})
        self.ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subscriptions}))

    def _receive(self, timeout: float) -> LiveMessage | None:
        try:
            frame = self.ws.recv(timeout=timeout)
        except TimeoutError:
            return None
        if isinstance(frame, str):
            info = json.loads(frame)
            if info.get('op') == 'advertise':
                for channel in info['channels']:
                    self.channels[channel['topic']] = channel
            return None
        if frame[0] != MESSAGE_DATA:
            return None
        sub_id, log_time = struct.unpack_from('<IQ', frame, 1)
        message = LiveMessage(self._topics_by_subscription[sub_id], log_time, frame[13:])
        self.pending.append(message)
        return message

    def receive(self, timeout: float) -> list[LiveMessage]:
        """Every message that arrives within ``timeout`` seconds (and those received before)."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                self._receive(left)
            except ConnectionClosed:
                break
        out, self.pending = self.pending, []
        return out

    def close(self) -> None:
        """Close the connection."""
        self.ws.close()

    def __enter__(self) -> LiveClient:
        """Use as a context manager."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the connection."""
        self.close()


def main(argv: list[str] | None = None) -> None:
    """Subscribe to every channel of a live view and count messages until Ctrl-C or SIGTERM."""
    import argparse
    import signal
    import sys

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument('--port', type=int, default=DEFAULT_PORT)
    parser.add_argument('--timeout', type=float, default=30.0, help='seconds to connect')
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    counts: dict[str, int] = {}
    try:
        with LiveClient(args.port, timeout=args.timeout) as client:
            client.subscribe(sorted(client.channels))
            print(f'subscribed to {len(client.channels)} channels', flush=True)
            while True:
                for message in client.receive(0.5):
                    counts[message.topic] = counts.get(message.topic, 0) + 1
    except (KeyboardInterrupt, SystemExit, ConnectionClosed):
        pass
    finally:
        print(json.dumps(counts), flush=True)


if __name__ == '__main__':
    main()
