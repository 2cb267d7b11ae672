"""Bare rclpy for libraries and hot paths: a node in its own context, rcl wait sets, one take.

A library's node (the lockstep client, the bag recorder, the benchmarks' probes) lives in its own
context, so it can be created and closed many times in a process, beside other such nodes. The
context installs no signal handlers: the application decides what Ctrl-C does (training saves a
checkpoint on KeyboardInterrupt). The node has no parameter services and no rosout publisher:
fewer entities in every wait of the hot path.

The hot paths wait on their subscriptions in a bare rcl wait set and take from them directly,
as ``rclpy.wait_for_message`` does: rclpy's executor costs about a third of a millisecond per
callback, as much as the sim's whole step.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rclpy
from rclpy.executors import Executor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from nav_sim.errors import is_interrupt

#: how pybind11 reports an exception raised while it converted a call's arguments
PYBIND11_CONVERSION_ERROR = 'Unable to convert call argument'


def own_node(name: str, namespace: str = '') -> tuple[rclpy.Context, Node]:
    """Return a new context without signal handlers and a bare node ``name`` in it.

    The caller closes both: ``node.destroy_node()``, then ``context.try_shutdown()``.
    """
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node(name, namespace=namespace or '/', context=context,
                                 start_parameter_services=False, enable_rosout=False)
    except BaseException:
        context.try_shutdown()
        raise
    return context, node


def subscription_wait_set(context: rclpy.Context, count: int) -> Any:
    """Return a bare rcl wait set for ``count`` subscriptions (reuse it: it is built once)."""
    return _rclpy.WaitSet(count, 0, 0, 0, 0, 0, context.handle)


def wait_ready(wait_set: Any, subscriptions: Sequence[Subscription],
               timeout_s: float) -> list[Subscription]:
    """Wait up to ``timeout_s`` on ``subscriptions``; return those with a message ready."""
    wait_set.clear_entities()
    for sub in subscriptions:
        wait_set.add_subscription(sub.handle)
    wait_set.wait(int(timeout_s * 1e9))
    ready = wait_set.get_ready_entities('subscription')
    return [sub for sub in subscriptions if sub.handle.pointer in ready]


def take(sub: Subscription) -> Any:
    """Take one message from a ready subscription (rclpy's ``take_message``); None if none.

    A Ctrl-C that pybind11 reports as another error raises KeyboardInterrupt
    (:func:`raise_interrupt`), so that an interrupted run saves its checkpoint instead of failing.
    """
    try:
        taken = sub.handle.take_message(sub.msg_type, sub.raw)
    except (RuntimeError, SystemError) as exc:
        raise_interrupt(exc)
        raise
    return None if taken is None else taken[0]


def spin_once(executor: Executor, timeout_s: float) -> None:
    """Run ``executor.spin_once``; a Ctrl-C reported as another error raises KeyboardInterrupt.

    The executor takes service responses and messages through the same pybind11 calls as
    :func:`take`.
    """
    try:
        executor.spin_once(timeout_sec=timeout_s)
    except (RuntimeError, SystemError) as exc:
        raise_interrupt(exc)
        raise


def raise_interrupt(exc: Exception) -> None:
    """Raise KeyboardInterrupt if ``exc`` is a Ctrl-C that an rclpy call reported as an error.

    A Ctrl-C (or a SIGTERM turned into KeyboardInterrupt) whose Python handler runs while
    pybind11 converts a call's arguments surfaces as ``RuntimeError: Unable to convert call
    argument ...``; one whose handler runs while the call builds its result, as the SystemError
    of :func:`nav_sim.errors.is_interrupt`.
    """
    if is_interrupt(exc) or (isinstance(exc, RuntimeError)
                             and str(exc).startswith(PYBIND11_CONVERSION_ERROR)):
        raise KeyboardInterrupt from exc
