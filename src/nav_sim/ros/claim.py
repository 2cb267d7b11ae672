"""One controlling client per sim: claims on the ROS graph, arbitrated by the sim.

``std_srvs/Trigger`` names no caller, so the sim cannot tell who resets it.  Instead a client
that resets and steps a sim (:class:`nav_sim.ros.client.SimClient`: the env, the evaluations,
the demo) *claims* it when it attaches: it publishes, latched, on ``<ns>/sim_claim``
(``std_msgs/String``) a JSON claim with its node, host, process id and the wall-clock time.
The sim (:class:`ClaimArbiter`) hears every claim and publishes, latched, on
``<ns>/sim_controller`` the claim that holds it: the earliest one whose publisher is still in
the graph.  The client waits for that answer.  Its own claim, or one of its own process (the
validation checklist attaches a second env to its own sim), and it controls the sim.  Another
process's claim, and it is refused at once with :class:`nav_sim.errors.SimInUseError` (one line
naming the namespace and the holder) and withdraws its claim.  The holder is never disturbed.

Observers never claim: the recorder, the live view, any subscriber.  In realtime mode the policy
node publishes ``cmd_vel`` without a claim and the evaluator that resets the sim claims it, so a
closed-loop evaluation or the demo (evaluator + policy node) is one claim, and a second
evaluator is refused.

A claim ends with its publisher: at once when its client closes or its process exits, and for a
process that was killed (SIGKILL, a crash) when DDS declares its participant gone, after Fast
DDS's participant lease (20 s by default; about 3 s on one machine in our tests).  The sim looks
again every :data:`RECHECK_S`.  To free a sim held by a crashed client at once, restart the sim.
"""

from __future__ import annotations

import json
import os
import socket
import time
from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from std_msgs.msg import String

from nav_sim.errors import SimInUseError, SimUnavailableError
from nav_sim.interface import CLAIM_TOPIC, CONTROLLER_TOPIC
from nav_sim.ros import qos
from nav_sim.ros.sim_graph import full_name

RECHECK_S = 1.0    # how often the sim looks for claims whose publisher has gone
FRESH_S = 5.0      # a claim just heard counts as live before the graph shows its publisher
#: ... and this long while the graph shows claim publishers whose node it cannot name yet
SETTLE_S = 30.0
#: the node name the rmw gives an endpoint before its participant has said which node owns it
UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'


def claim_is_live(node: str, live: set[str], seen: set[str], heard: dict[str, float],
                  now: float, settling: bool = False) -> bool:
    """Tell whether ``node``'s claim still stands.

    A claim is live while its node publishes claims (``live``), and dead once the graph has
    shown that node (``seen``) and shows it no longer.  One whose publisher the graph has not
    named yet is live for FRESH_S after it was heard: discovery may show it a moment later.  On
    a loaded machine the node that owns an endpoint can be named much later than the endpoint
    appears (the rmw shows it as ``UNKNOWN_NODE`` meanwhile); while it does (``settling``), an
    unnamed claim stays live up to SETTLE_S, so that a claim is never dropped for slow discovery
    while its client holds the sim.
    """
    if node in live:
        return True
    if node in seen:
        return False
    age = now - heard.get(node, -1e18)
    return age < FRESH_S or (settling and age < SETTLE_S)


def holder_of(claims: dict[str, dict[str, Any]], live: set[str], seen: set[str],
              heard: dict[str, float], now: float,
              settling: bool = False) -> dict[str, Any] | None:
    """Return the claim that holds the sim: the earliest live one (None without any).

    :func:`claim_is_live` says which claims are live; ties go to the node name.
    """
    alive = [claim for node, claim in claims.items()
             if claim_is_live(node, live, seen, heard, now, settling)]
    return min(alive, key=lambda c: (c.get('since_ns', 0), c['node'])) if alive else None


def _parse(msg: String) -> dict[str, Any] | None:
    try:
        claim = json.loads(msg.data)
        return claim if isinstance(claim, dict) and isinstance(claim.get('node'), str) else None
    except ValueError:
        return None


class ClaimArbiter:
    """The sim's side: hear the claims, publish the one that holds the sim."""

    def __init__(self, node: Node) -> None:
        """Subscribe to the claims and publish the holder (latched) from now on."""
        self.node = node
        self.claims: dict[str, dict[str, Any]] = {}
        self.heard: dict[str, float] = {}
        self.seen: set[str] = set()  # claiming nodes the graph has shown
        self.holder: dict[str, Any] | None = None
        self._published: str | None = None
        self._pub = node.create_publisher(String, CONTROLLER_TOPIC, qos.LATCHED)
        node.create_subscription(String, CLAIM_TOPIC, self._on_claim, qos.LATCHED_MANY)
        node.create_timer(RECHECK_S, self.update)
        self.update()

    def _on_claim(self, msg: String) -> None:
        claim = _parse(msg)
        if claim is not None:
            self.claims[claim['node']] = claim
            self.heard[claim['node']] = time.monotonic()
            self.update()

    def update(self) -> None:
        """Decide the holder again (a claim withdrawn, a client gone) and publish a change."""
        topic = self.node.resolve_topic_name(CLAIM_TOPIC)
        publishers = self.node.get_publishers_info_by_topic(topic)
        live = {full_name(i.node_namespace, i.node_name) for i in publishers
                if i.node_name != UNKNOWN_NODE}
        settling = any(i.node_name == UNKNOWN_NODE for i in publishers)  # slow discovery
        now = time.monotonic()
        self.seen |= live & set(self.claims)
        for node in [n for n in self.claims
                     if not claim_is_live(n, live, self.seen, self.heard, now, settling)]:
            del self.claims[node]  # its client has gone: its claim with it
            self.seen.discard(node)
            self.heard.pop(node, None)
        self.holder = holder_of(self.claims, live, self.seen, self.heard, now, settling)
        text = json.dumps(self.holder or {})
        if text != self._published:
            self._pub.publish(String(data=text))
            self._published = text


class Claim:
    """A client's claim on the sim of its node's namespace."""

    def __init__(self, node: Node) -> None:
        """Listen to the sim's answers (latched) from now on."""
        self.node = node
        self.answer: dict[str, Any] | None = None
        self.mine: dict[str, Any] | None = None
        self._publisher: Any = None
        node.create_subscription(String, CONTROLLER_TOPIC, self._on_answer, qos.LATCHED)

    def _on_answer(self, msg: String) -> None:
        self.answer = _parse(msg) or {}

    @property
    def held(self) -> bool:
        """Tell whether this client holds (or shares) the sim."""
        return self.mine is not None

    def acquire(self, spin: Callable[[float], None], where: str, timeout: float,
                abort: Callable[[], str | None] | None = None) -> None:
        """Claim the sim, or raise SimInUseError naming the process that holds it.

        ``abort`` is polled while waiting for the answer: a message from it (the sim process
        this client started has died) ends the wait at once, with that message.
        """
        if self.mine is not None:
            return
        mine = {'node': self.node.get_fully_qualified_name(), 'host': socket.gethostname(),
                'pid': os.getpid(), 'since_ns': time.time_ns()}
        self._publisher = self.node.create_publisher(String, CLAIM_TOPIC, qos.LATCHED)
        self._publisher.publish(String(data=json.dumps(mine)))
        deadline = time.monotonic() + timeout
        while not self._decided(mine):
            reason = abort() if abort is not None else None
            if reason:
                self._withdraw()
                raise SimUnavailableError(f'nav_sim in {where} stopped before it answered '
                                          f'its claim: {reason}')
            if time.monotonic() >= deadline:
                self._withdraw()
                raise SimUnavailableError(
                    f'the sim in {where} did not answer its claim within {timeout} s (a sim '
                    'of an older visnav?); restart it with `ros2 run nav_sim sim_node`')
            spin(0.05)
        answer = self.answer or {}
        if (answer.get('host'), answer.get('pid')) != (mine['host'], mine['pid']):
            self._withdraw()
            raise SimInUseError(
                f'the sim in {where} is in use: {answer["node"]} (process {answer.get("pid")} '
                f'on {answer.get("host")}) controls it; one controlling client at a time: stop '
                'that one, or start another sim in its own namespace (a killed client releases '
                'it within 20 s; docs/simulation.md)')
        self.mine = mine

    def _decided(self, mine: dict[str, Any]) -> bool:
        """Tell whether the sim's answer settles our claim: ours, ours to share, or earlier."""
        answer = self.answer
        if not answer:
            return False
        if answer.get('node') == mine['node']:
            return True
        return (answer.get('since_ns', 0), answer['node']) < (mine['since_ns'], mine['node'])

    def _withdraw(self) -> None:
        if self._publisher is not None:
            self.node.destroy_publisher(self._publisher)
            self._publisher = None
