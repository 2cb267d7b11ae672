"""A lockstep client of the ``nav_sim`` node: publish ``cmd_vel``, receive the period's messages.

Used by the env, the evaluation tools, the demo, the tests and the benchmark.  It runs its own
rclpy context and spins its ``SingleThreadedExecutor`` in the calling thread while it waits (no
thread hand-over on the hot path), so it can be created and closed many times in a process.
Every wait is bounded: a sim that does not answer, or is gone, is a SimUnavailableError.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import Image
from std_srvs.srv import Trigger

from nav_sim import interface
from nav_sim.core.events import EVENT_NONE
from nav_sim.errors import FrameSyncError, ScenarioError, SimConflictError, SimUnavailableError
from nav_sim.ros import messages as ros_msgs
from nav_sim.ros import qos, sim_graph
from nav_sim.ros.bare import own_node, spin_once, subscription_wait_set, take, wait_ready
from nav_sim.ros.claim import Claim

POLL_S = 0.25
RESET_RETRY_S = 1.0
RESEND_S = 2.0  # a service request with no answer by then is sent again (see _call)
NAMES_WAIT_S = 3.0  # for the names of conflicting sims still being discovered


@dataclass(frozen=True)
class Frame:
    """The messages of one control period, matched by stamp."""

    stamp_ns: int
    image: Image
    event: dict[str, Any]
    pose: tuple[float, float, float]
    twist: tuple[float, float]

    @property
    def period(self) -> int:
        """Control periods the sim had run when it published this frame."""
        return int(self.event['period'])


class SimClient:
    """Drive a running nav_sim node in lockstep."""

    def __init__(self, namespace: str = '', timeout: float = 10.0,
                 node_name: str = 'visnav_client', cmd_vel_stamped: bool = False) -> None:
        """Create the client's own context and node in ``namespace``.

        Every wait is bounded by ``timeout`` seconds.  ``cmd_vel_stamped`` sends ``cmd_vel`` as
        TwistStamped (the sim's setting of the same name must agree: :meth:`wait_for_sim` says
        so if it does not).  ``namespace`` follows :func:`nav_sim.interface.absolute_namespace`:
        ``robot1`` is ``/robot1``, and a name ROS would refuse raises ValueError in one line.
        """
        self.cmd_vel_stamped = cmd_vel_stamped
        self.namespace = interface.absolute_namespace(namespace)  # the graph's one rule
        self.timeout = timeout
        # its own context without signal handlers (the application owns Ctrl-C), a bare node
        self.context, self.node = own_node(node_name, self.namespace)
        self._partial: dict[int, dict[str, Any]] = {}
        self._latest: Frame | None = None
        self.goal: tuple[float, float] | None = None
        n = self.node
        self._subs = [
            n.create_subscription(Image, interface.IMAGE_TOPIC, self._part('image'),
                                  qos.OBSERVATION),
            n.create_subscription(DiagnosticArray, interface.EVENT_TOPIC, self._part('event'),
                                  qos.OBSERVATION),
        ]
        # The lockstep hot path waits on these two subscriptions directly, as
        # rclpy.wait_for_message does: the executor's per-wait bookkeeping costs more than the
        # sim's whole control period.  Services and the latched goal go through the executor.
        self._wait_set = subscription_wait_set(self.context, len(self._subs))
        n.create_subscription(PoseStamped, interface.GOAL_TOPIC, self._on_goal, qos.LATCHED)
        self.pub_cmd = n.create_publisher(ros_msgs.cmd_vel_class(cmd_vel_stamped),
                                          interface.CMD_VEL_TOPIC, qos.CONTROL)
        self.cli_reset = n.create_client(Trigger, interface.RESET_SERVICE)
        self.cli_stop = n.create_client(Trigger, interface.STOP_SERVICE)
        self.cli_params = n.create_client(SetParameters, interface.PARAMETERS_SERVICE)
        self.claim = Claim(n)  # one controlling client per sim: taken by wait_for_sim
        self._executor = SingleThreadedExecutor(context=self.context)
        self._executor.add_node(n)

    # --- plumbing -------------------------------------------------------------------------
    def _part(self, kind: str):  # noqa: ANN202 - subscription callback factory
        def callback(msg: Any) -> None:
            stamp = ros_msgs.stamp_to_ns(msg.header.stamp)
            parts = self._partial.setdefault(stamp, {})
            parts[kind] = msg
            if len(parts) == 2:
                del self._partial[stamp]
                for old in [s for s in self._partial if s < stamp]:
                    del self._partial[old]
                self._latest = _frame(stamp, parts)
        return callback

    def _on_goal(self, msg: PoseStamped) -> None:
        self.goal = (msg.pose.position.x, msg.pose.position.y)

    @property
    def where(self) -> str:
        """Say where the sim is looked for, for messages."""
        return f"namespace '{self.namespace or '/'}'"

    def _matched(self) -> bool:
        """Our cmd_vel reaches a subscriber and our observation readers see publishers."""
        return (self.pub_cmd.get_subscription_count() > 0
                and all(sub.get_publisher_count() > 0 for sub in self._subs))

    def sim_present(self) -> bool:
        """Tell whether some node publishes the camera topic of this namespace."""
        return self.node.count_publishers(self.node.resolve_topic_name(interface.IMAGE_TOPIC)) > 0

    def sim_nodes(self) -> list[str]:
        """Name the nodes that publish this namespace's camera or serve its ``reset``."""
        return sim_graph.sim_nodes(self.node)

    def find_sims(self, timeout: float) -> list[str]:
        """Wait up to ``timeout`` s for a sim to show in the namespace; name what is there."""
        deadline = time.monotonic() + timeout
        names = self.sim_nodes()
        while not names and time.monotonic() < deadline:
            self.spin_once(min(0.05, max(deadline - time.monotonic(), 0)))
            names = self.sim_nodes()
        return names

    def check_single_sim(self, by_name: bool = False) -> None:
        """Raise SimConflictError if more than one node publishes the camera or serves reset.

        Two sims in one namespace would both step on every ``cmd_vel`` and both answer; the
        observations and rewards would mix their worlds.  Counting publishers and servers is
        cheap (each reset does it); ``by_name`` also catches a camera publisher and a reset
        server that are different nodes (when attaching).
        """
        if sim_graph.sim_count(self.node) <= 1 and not by_name:
            return
        names = self.sim_nodes()
        if max(sim_graph.sim_count(self.node), len(names)) <= 1:
            return
        deadline = time.monotonic() + NAMES_WAIT_S  # a node's name comes after its endpoints
        while (any(sim_graph.UNKNOWN_NODE in name for name in names)
               and time.monotonic() < deadline):
            self.spin_once(0.05)
            names = self.sim_nodes()
        if max(sim_graph.sim_count(self.node), len(names)) <= 1:
            return  # an unnamed endpoint was the one sim's own
        raise SimConflictError(sim_graph.conflict_message(self.node, names))

    def spin_until(self, done: Callable[[], bool], limit: float) -> bool:
        """Process callbacks until ``done()`` or ``limit`` seconds pass; False on time-out."""
        deadline = time.monotonic() + limit
        next_check = time.monotonic() + POLL_S
        while not done():
            now = time.monotonic()
            if now >= deadline:
                return False
            self.spin_once(min(deadline - now, POLL_S))
            if time.monotonic() >= next_check:
                if not self.sim_present():
                    raise SimUnavailableError(
                        f'nav_sim in {self.where} is gone (no camera publisher); restart it '
                        'with `ros2 run nav_sim sim_node`')
                next_check = time.monotonic() + POLL_S
        return True

    def spin_once(self, timeout: float = 0.0) -> None:
        """Process at most one callback of the client's node, waiting up to ``timeout`` s.

        A Ctrl-C raises KeyboardInterrupt, also where rclpy reports it as another error
        (:func:`nav_sim.ros.bare.spin_once`).
        """
        spin_once(self._executor, timeout)

    def _take_observations(self, timeout: float) -> None:
        """Wait up to ``timeout`` s on the observation subscriptions and take what arrived."""
        for sub in wait_ready(self._wait_set, self._subs, timeout):
            message = take(sub)
            if message is not None:
                sub.callback(message)

    def _wait_frame(self, predicate: Callable[[Frame], bool], what: str,
                    limit: float | None = None) -> Frame | None:
        """Return the first frame satisfying ``predicate``.

        Raises after ``self.timeout`` s, or returns None after ``limit`` s if one is given (the
        caller may then retry), each after a last look of up to ``POLL_S``.
        """
        def arrived() -> bool:
            return self._latest is not None and predicate(self._latest)

        deadline = time.monotonic() + (limit if limit is not None else self.timeout)
        while not arrived():
            left = deadline - time.monotonic()
            if left <= 0:
                break
            self._take_observations(min(left, POLL_S))
            if not arrived() and not self.sim_present():
                raise SimUnavailableError(
                    f'nav_sim in {self.where} is gone (no camera publisher) while waiting for '
                    f'{what}; restart it with `ros2 run nav_sim sim_node`')
        grace = time.monotonic() + POLL_S  # a last look: this process may have slept past
        while not arrived() and grace > time.monotonic():  # its deadline (SIGSTOP, a suspend)
            self._take_observations(max(grace - time.monotonic(), 0.0))
        if not arrived():
            if limit is not None:
                return None
            raise SimUnavailableError(
                f'no {what} from nav_sim in {self.where} within {self.timeout} s; is '
                '`ros2 run nav_sim sim_node` running there (in lockstep mode)?')
        assert self._latest is not None
        return self._latest

    def _call(self, client: Any, request: Any, what: str) -> Any:
        if not client.wait_for_service(timeout_sec=self.timeout):
            raise SimUnavailableError(
                f'service {client.srv_name} of nav_sim in {self.where} not available within '
                f'{self.timeout} s; start the sim with `ros2 run nav_sim sim_node`')
        # A service's response is lost if it is sent before the server has matched this
        # client's response reader (Fast DDS waits 100 ms for that, then drops it), which
        # discovery under load can outlast.  The sim's services are idempotent (the same
        # parameters, a reset to the same seed, stop), so the request is sent again every
        # RESEND_S; only the newest request's answer counts (a reset answers with its stamp).
        deadline = time.monotonic() + self.timeout
        while True:
            future = client.call_async(request)
            left = deadline - time.monotonic()
            if self.spin_until(future.done, max(min(RESEND_S, left), 0.0)):
                return future.result()
            client.remove_pending_request(future)
            if time.monotonic() >= deadline:
                raise SimUnavailableError(f'{what} of nav_sim in {self.where} timed out after '
                                          f'{self.timeout} s')

    # --- public API -----------------------------------------------------------------------
    def wait_for_sim(self, timeout: float | None = None,
                     abort: Callable[[], str | None] | None = None,
                     started: Callable[[], bool] | None = None) -> None:
        """Block until the sim's camera topic and reset service exist, or raise with advice.

        ``abort`` is polled while waiting; a message from it ends the wait at once (e.g. the
        sim process this client started has died).  ``started`` (the sim process this client
        started says it is up) must hold too: another sim answering is not this one.  More than
        one sim in the namespace raises SimConflictError (discovery may show a second one only
        later: each reset checks again).  Found, the sim is claimed for this process
        (:mod:`nav_sim.ros.claim`): a client of another process that controls it already
        raises SimInUseError.
        """
        limit = timeout or self.timeout
        deadline = time.monotonic() + limit
        while not (self.sim_present() and self.cli_reset.service_is_ready()
                   and self._matched() and (started is None or started())):
            self.check_single_sim()
            if self.pub_cmd.get_subscription_count() == 0 and self.sim_present():
                sim_graph.refuse_cmd_vel_mismatch(self.node, self.cmd_vel_stamped, self.where)
            reason = abort() if abort is not None else None
            if reason:
                raise SimUnavailableError(f'nav_sim in {self.where} did not start: {reason}')
            if time.monotonic() > deadline:
                raise SimUnavailableError(
                    f'no nav_sim node found in {self.where} after {limit} s; start one with '
                    '`ros2 run nav_sim sim_node` (add `--ros-args -r __ns:=/NS` for a namespace)')
            self.spin_once(0.05)
        self.check_single_sim(by_name=True)
        self.claim.acquire(self.spin_once, self.where, limit, abort)

    def set_parameters(self, **values: Any) -> None:
        """Set sim_node parameters (e.g. seed, split); raises ScenarioError if refused."""
        request = SetParameters.Request()
        request.parameters = [ros_msgs.parameter_msg(k, v) for k, v in values.items()]
        response = self._call(self.cli_params, request, 'set_parameters')
        for (key, value), result in zip(values.items(), response.results, strict=False):
            if not result.successful:
                raise ScenarioError(f'sim_node refused {key}={value!r}: {result.reason}')

    def reset(self, seed: int | None = None, split: str | None = None) -> tuple[Frame, dict]:
        """Start an episode; returns its first frame and the scenario the sim loaded.

        Refuses (SimConflictError) if a second sim has appeared in the namespace.
        """
        self.check_single_sim()
        values = {k: v for k, v in (('seed', seed), ('split', split)) if v is not None}
        if values:
            self.set_parameters(**values)
        # Discovery can report a match before the sim's publishers deliver to this client: if
        # the reset frame does not come, reset again (the same seed gives the same scenario).
        deadline = time.monotonic() + self.timeout
        while True:
            scenario = self.request_reset()
            stamp = int(scenario['stamp_ns'])
            left = deadline - time.monotonic()
            frame = self._wait_frame(lambda f, s=stamp: f.stamp_ns >= s,
                                     'first observation after reset',
                                     limit=max(min(RESET_RETRY_S, left), 0.0))
            if frame is not None:
                break
            if time.monotonic() >= deadline:
                raise SimUnavailableError(
                    f'no first observation after reset from nav_sim in {self.where} within '
                    f'{self.timeout} s; is `ros2 run nav_sim sim_node` running there (in '
                    'lockstep mode)?')
        if frame.stamp_ns != stamp:
            raise FrameSyncError(f'expected the reset frame {stamp} ns, got {frame.stamp_ns} ns')
        return frame, scenario

    def request_reset(self) -> dict[str, Any]:
        """Call the sim's ``reset`` service once; return the scenario it loaded (JSON decoded).

        The scenario names the reset frame's ``stamp_ns``, ``episode`` and ``period``; this
        does not wait for the frame (:meth:`reset` does).  A refusal raises SimConflictError
        (another sim in the namespace) or ScenarioError.
        """
        response = self._call(self.cli_reset, Trigger.Request(), 'reset')
        if not response.success:
            if response.message.startswith(sim_graph.CONFLICT):  # the sim sees another
                raise SimConflictError(response.message)
            raise ScenarioError(response.message)
        return json.loads(response.message)

    def step(self, linear: float, angular: float, after: Frame) -> Frame:
        """Publish one cmd_vel and return the frame of the control period it caused."""
        msg = ros_msgs.cmd_vel_msg(
            linear, angular, self.node.get_clock().now().to_msg() if self.cmd_vel_stamped
            else None)
        expected = after.period + 1
        self.pub_cmd.publish(msg)
        frame = self._wait_frame(lambda f: f.period >= expected, 'observation after cmd_vel')
        if frame.period != expected:
            self.check_single_sim()  # two sims answering is the likelier cause: say so
            raise FrameSyncError(
                f'expected control period {expected}, got {frame.period}: another client may '
                f'be driving the sim in {self.where}, or frames were dropped')
        return frame

    def stop(self) -> list[float]:
        """Stop the motors; returns the wheel speeds the sim reports after stopping."""
        response = self._call(self.cli_stop, Trigger.Request(), 'stop')
        return [float(v) for v in json.loads(response.message)['wheels']]

    def close(self) -> None:
        """Destroy the node, the executor and the context."""
        if self.context.ok():
            self._executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
            self.context.try_shutdown()

    def __enter__(self) -> SimClient:
        """Use as a context manager that closes the client."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the client."""
        self.close()


def _frame(stamp: int, parts: dict[str, Any]) -> Frame:
    event = ros_msgs.parse_event(parts['event']) or {'event': EVENT_NONE, 'period': -1}
    pose = (event.get('x', math.nan), event.get('y', math.nan), event.get('yaw', math.nan))
    twist = (event.get('linear', math.nan), event.get('angular', math.nan))
    return Frame(stamp, parts['image'], event, pose, twist)
