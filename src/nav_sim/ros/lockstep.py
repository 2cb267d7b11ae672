"""The lockstep sim's event loop: block until a command, a request or shutdown arrives.

rclpy's executor costs about a third of a millisecond per callback, as much as the sim's step
and render together, so the lockstep hot path (one ``cmd_vel`` = one control period) takes the
command from a bare rcl wait set, as ``rclpy.wait_for_message`` does, and leaves everything else
to the executor.  The wait set holds every entity of the node and blocks without a time-out: an
idle sim uses no CPU, and a request, a parameter change or Ctrl-C wakes it at once.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from rclpy.executors import Executor
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerGuardCondition
from rclpy.subscription import Subscription

from nav_sim.ros.stop_request import StopRequest


class NodeWaitSet:
    """Every entity of one node (and some extra guard conditions) in a bare rcl wait set.

    The wait set is rebuilt when the node gains or loses an entity, so a timer, subscription or
    service created later is waited on too.
    """

    def __init__(self, node: Node, extra_guards: Iterable[GuardCondition] = ()) -> None:
        """Wait on ``node``'s entities and ``extra_guards`` (built at the first wait)."""
        self.node = node
        self.extra_guards = tuple(extra_guards)
        self._entities: tuple[tuple[Any, ...], ...] = ()
        self._wait_set: Any = None

    def _current(self) -> tuple[tuple[Any, ...], ...]:
        n = self.node
        return (tuple(n.subscriptions), tuple(n.guards), tuple(n.timers), tuple(n.clients),
                tuple(n.services), tuple(n.waitables))

    def _build(self, entities: tuple[tuple[Any, ...], ...]) -> None:
        subs, guards, timers, clients, services, waitables = entities
        counts = [len(subs), len(guards) + len(self.extra_guards), len(timers), len(clients),
                  len(services), 0]
        for waitable in waitables:
            extra = waitable.get_num_entities()
            for i, name in enumerate(('num_subscriptions', 'num_guard_conditions', 'num_timers',
                                      'num_clients', 'num_services', 'num_events')):
                counts[i] += getattr(extra, name)
        self._wait_set = _rclpy.WaitSet(*counts, self.node.context.handle)
        self._entities = entities

    def wait(self, subscription: Subscription, timeout_ns: int = -1) -> tuple[bool, bool]:
        """Block until something is ready (or ``timeout_ns``, -1 = forever).

        Returns ``(subscription ready, anything else of the node ready)``; a ready guard
        condition of the node is triggered again so the executor still sees it.
        """
        entities = self._current()
        if entities != self._entities:
            self._build(entities)
        subs, guards, timers, clients, services, waitables = entities
        ws = self._wait_set
        ws.clear_entities()
        for sub in subs:
            ws.add_subscription(sub.handle)
        for guard in guards + self.extra_guards:
            ws.add_guard_condition(guard.handle)
        for timer in timers:
            ws.add_timer(timer.handle)
        for client in clients:
            ws.add_client(client.handle)
        for service in services:
            ws.add_service(service.handle)
        for waitable in waitables:
            waitable.add_to_wait_set(ws)
        ws.wait(timeout_ns)
        ready_subs = ws.get_ready_entities('subscription')
        mine = subscription.handle.pointer in ready_subs
        other = len(ready_subs) > int(mine)
        ready_guards = ws.get_ready_entities('guard_condition')
        for guard in guards:
            if guard.handle.pointer in ready_guards:
                guard.trigger()  # rcl_wait consumed the trigger; the executor must see it
                other = True
        for kind in ('timer', 'client', 'service'):
            other = other or bool(ws.get_ready_entities(kind))
        other = other or any(waitable.is_ready(ws) for waitable in waitables)
        return mine, other


def spin_lockstep(node: Node, executor: Executor, subscription: Subscription,
                  callback: Callable[[Any], None] | None = None,
                  stop: StopRequest | None = None) -> None:
    """Serve ``subscription`` directly and hand everything else of ``node`` to ``executor``.

    Returns when the node's context shuts down (``rclpy.shutdown``) or ``stop`` is set (Ctrl-C,
    SIGTERM).  rclpy's SIGINT guard condition and one that shutdown triggers are in the wait set,
    so neither waits for the next command.  rclpy's handler wakes the wait before its thread
    shuts the context down, so the stop flag ends the loop, not the context alone.
    """
    context = node.context
    handle = callback or subscription.callback
    wake = GuardCondition(None, None, context=context)
    sigint = SignalHandlerGuardCondition(context)
    context.on_shutdown(wake.trigger)
    waits = NodeWaitSet(node, (wake, sigint))
    try:
        while context.ok() and not stop:
            mine, other = waits.wait(subscription)
            if mine:  # rclpy's own handlers take Ctrl-C here: no KeyboardInterrupt (bare.take)
                taken = subscription.handle.take_message(subscription.msg_type,
                                                         subscription.raw)
                if taken is not None:
                    handle(taken[0])
            if other and context.ok():
                executor.spin_once(timeout_sec=0.0)
    finally:
        sigint.destroy()
        wake.destroy()
