"""One controlling client per sim: claims on the ROS graph, arbitrated by the sim.

``std_srvs/Trigger`` names no caller, so the sim cannot tell who resets it.  Instead a client
that resets and steps a sim (:class:`nav_sim.ros.client.SimClient`: the env, the evaluations,
the demo) *claims* it when it attaches: it publishes, latched, on ``<ns>/sim_claim``
(``std_msgs/String``) a JSON claim with its node, host, process id and the wall-clock time.
The sim (:class:`ClaimArbiter`) hears every claim and publishes, latched, on
``<ns>/sim_controller`` the claim that holds it, with every claim it has heard (``heard``: key and
stamp).  A claim that holds the sim holds it as long as its publisher is in the graph; a
claim heard later never displaces it, even one stamped earlier (two clients started at once).
Only a free sim goes to a claim: the earliest of those heard.  The client waits until the
answer lists its claim as heard.  Its own claim, or one of its own process (the
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
Claims are told apart by node, host and process, so two processes whose clients share a node
name are still two claims.  The sim logs every change of holder and every claim it drops.
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
from nav_sim.interface import CLAIM_TOPIC, CONTROLLER_TOPIC, full_name
from nav_sim.ros import qos
from nav_sim.ros.sim_graph import UNKNOWN_NODE

RECHECK_S = 1.0    # how often the sim looks for claims whose publisher has gone
FRESH_S = 5.0      # a claim just heard counts as live before the graph names its publisher
SETTLE_S = 30.0    # ... the holder's, while the graph shows claim publishers it cannot name

Key = tuple[str, str, int]  # a claim's node, host and process: names may repeat across processes


def key_of(claim: dict[str, Any]) -> Key:
    """Return the key that tells one client's claim from another's."""
    return claim['node'], str(claim.get('host')), int(claim.get('pid') or 0)


def claim_is_live(named: bool, seen: bool, age: float, settling: bool = False,
                  holding: bool = False) -> bool:
    """Tell whether a claim heard ``age`` seconds ago still stands.

    A claim is live while the graph names its node among the claim publishers (``named``), and
    dead once the graph has shown its node (``seen``) and shows it no longer.  One whose
    publisher the graph has not named yet is live for FRESH_S after it was heard: discovery may
    name it a moment later.  On a loaded machine the graph can show an endpoint some seconds
    before it names the node that owns it (the rmw's ``UNKNOWN_NODE``).  While it does
    (``settling``), the claim that holds the sim (``holding``) stays live up to SETTLE_S, so
    that slow discovery does not free a sim that its client is stepping.  Other unnamed claims
    (refused clients, which withdraw at once) keep FRESH_S, so that they never stand in for a
    holder that has gone.
    """
    if named:
        return True
    if seen:
        return False
    return age < FRESH_S or (settling and holding and age < SETTLE_S)


def holder_of(claims: dict[Key, dict[str, Any]],
              holding: Key | None = None) -> dict[str, Any] | None:
    """Return the claim that holds the sim (None without any).

    The claim that holds it (key ``holding``) keeps it while it is among ``claims``, the live
    ones (:func:`claim_is_live`): its client was told so and steps the sim.  A free sim goes to
    the earliest claim, ties to the node name.
    """
    if holding in claims:
        return claims[holding]
    return min(claims.values(), key=lambda c: (c.get('since_ns', 0), c['node']),
               default=None)


def heard_entry(claim: dict[str, Any]) -> list[Any]:
    """Return a claim as the sim's answer lists it among the claims heard: key and stamp."""
    return [*key_of(claim), claim.get('since_ns', 0)]


def settles(answer: dict[str, Any] | None, mine: dict[str, Any]) -> bool:
    """Tell whether the sim's answer settles the claim ``mine``: the sim has heard it.

    The answer names the holder: ``mine``, or one of its own process to share, or another
    process's, which refuses it.  An answer that has not heard this very claim (key and stamp)
    settles nothing: it may be one the sim published before, for a client of the same name.
    """
    return heard_entry(mine) in (answer or {}).get('heard', [])


def _parse(msg: String) -> dict[str, Any] | None:
    try:
        claim = json.loads(msg.data)
        if not isinstance(claim, dict) or not isinstance(claim.get('node'), str):
            return None
        key_of(claim)  # a process id that is no number: not a claim
        return claim
    except (ValueError, TypeError):
        return None


class ClaimArbiter:
    """The sim's side: hear the claims, publish the one that holds the sim."""

    def __init__(self, node: Node) -> None:
        """Subscribe to the claims and publish the holder (latched) from now on."""
        self.node = node
        self.claims: dict[Key, dict[str, Any]] = {}
        self.heard: dict[Key, float] = {}
        self.seen: set[Key] = set()  # claims whose node the graph has named
        self.holder: dict[str, Any] | None = None
        self._published: str | None = None
        self._pub = node.create_publisher(String, CONTROLLER_TOPIC, qos.LATCHED)
        node.create_subscription(String, CLAIM_TOPIC, self._on_claim, qos.LATCHED_MANY)
        node.create_timer(RECHECK_S, self.update)
        self.update()

    def _on_claim(self, msg: String) -> None:
        claim = _parse(msg)
        if claim is not None:
            key = key_of(claim)
            if self.claims.get(key) != claim:  # a new claim, or one made again
                self.seen.discard(key)
            self.claims[key] = claim
            self.heard[key] = time.monotonic()
            self.update()

    def update(self) -> None:
        """Decide the holder again (a claim withdrawn, a client gone) and publish a change."""
        topic = self.node.resolve_topic_name(CLAIM_TOPIC)
        publishers = self.node.get_publishers_info_by_topic(topic)
        live = {full_name(i.node_namespace, i.node_name) for i in publishers
                if i.node_name != UNKNOWN_NODE}
        settling = any(i.node_name == UNKNOWN_NODE for i in publishers)  # not all named yet
        now = time.monotonic()
        holding = key_of(self.holder) if self.holder else None
        for key, claim in list(self.claims.items()):
            named = claim['node'] in live
            if named:
                self.seen.add(key)
            seen, age = key in self.seen, now - self.heard[key]
            if not claim_is_live(named, seen, age, settling, key == holding):
                del self.claims[key]  # its client has gone: its claim with it
                self.seen.discard(key)
                self.heard.pop(key, None)
                why = ('its node left the graph' if seen
                       else f'the graph did not name its node within {age:.0f} s')
                self.node.get_logger().info(
                    f'the claim of {claim["node"]} (process {claim.get("pid")}) ended: {why}')
        self.holder = holder_of(self.claims, holding)
        held = key_of(self.holder) if self.holder else None
        if self._published is None or held != holding:
            self.node.get_logger().info(
                f'held by {self.holder["node"]} (process {self.holder.get("pid")})'
                if self.holder else 'held by no client')
        heard = sorted(heard_entry(c) for c in self.claims.values())
        text = json.dumps({**(self.holder or {}), 'heard': heard})
        if text != self._published:  # a new holder, or a claim heard or ended
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
        while not settles(self.answer, mine):
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

    def _withdraw(self) -> None:
        if self._publisher is not None:
            self.node.destroy_publisher(self._publisher)
            self._publisher = None
