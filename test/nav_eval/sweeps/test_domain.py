"""Host-local ROS domain reservations: unique while held, freed on release, isolating sims."""

from __future__ import annotations

import random
import subprocess
import sys
import time

import pytest

from helpers import wait_until
from nav_eval.sweeps.domain import DomainUnavailableError, reserve_any_domain, reserve_domain
from nav_sim.ros.process import SimProcess

DISCOVERY_S = 60.0
#: the shortest window in which no probe may see the other domain's sim
MIN_WINDOW_S = 2.0


def test_held_ids_are_unique_and_come_back_on_release():
    held = [reserve_domain(rng=random.Random(0)) for _ in range(5)]
    try:
        ids = [h.domain_id for h in held]
        assert len(set(ids)) == 5
        with pytest.raises(DomainUnavailableError, match='reserved on this host'):
            reserve_domain([ids[0]])
        held[0].release()
        again = reserve_domain([ids[0]])
        assert again.domain_id == ids[0]
        again.release()
    finally:
        for h in held:
            h.release()


def test_another_process_cannot_take_a_held_id():
    with reserve_any_domain() as mine:
        code = ('import sys\n'
                'from nav_eval.sweeps.domain import reserve_domain, DomainUnavailableError\n'
                f'try:\n    reserve_domain([{mine.domain_id}])\n'
                'except DomainUnavailableError:\n    sys.exit(3)\n')
        assert subprocess.run([sys.executable, '-c', code], timeout=60).returncode == 3
        env = mine.environment({})
        assert env == {'ROS_DOMAIN_ID': str(mine.domain_id),
                       'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}


def _camera_publishers(node) -> int:
    """Camera publishers in the node's namespace, as its domain shows them to it."""
    return node.count_publishers(node.resolve_topic_name('camera/image_raw'))


def _control_discovery_s(domain_id: int, namespace: str, probe) -> float:
    """Seconds ``probe`` takes to discover a second camera publisher in its own domain.

    The publisher is another DDS participant (its own context), as a sim of another domain
    would be if domains leaked; the probe must see it, then see it go.
    """
    import rclpy
    from sensor_msgs.msg import Image
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = rclpy.create_node('domain_control', namespace=namespace, context=context)
        started = time.monotonic()
        node.create_publisher(Image, 'camera/image_raw', 1)
        wait_until(lambda: _camera_publishers(probe) == 2, DISCOVERY_S,
                   f'a second camera publisher in domain {domain_id}, seen by its probe',
                   details=lambda: f'it sees {_camera_publishers(probe)}')
        took = time.monotonic() - started
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    wait_until(lambda: _camera_publishers(probe) == 1, DISCOVERY_S,
               f'the second camera publisher in domain {domain_id} gone',
               details=lambda: f'its probe sees {_camera_publishers(probe)}')
    return took


def _observe(probes: list, seconds: float) -> list[list[int]]:
    """Camera publishers each probe sees, every 0.1 s for ``seconds``."""
    seen: list[list[int]] = [[] for _ in probes]
    end = time.monotonic() + seconds
    while True:
        for counts, probe in zip(seen, probes, strict=True):
            counts.append(_camera_publishers(probe))
        left = end - time.monotonic()
        if left <= 0:
            return seen
        time.sleep(min(0.1, left))


def test_two_sims_in_one_namespace_but_different_domains_do_not_see_each_other(namespace):
    """Each domain's probe sees its sim and a second publisher in its domain, never the other sim.

    Two domains share no traffic, so nothing orders what one probe sees against the other
    domain: the other sim's absence is shown over a window instead.  The window comes after a
    positive control, the same probe discovering a second camera publisher of its own domain
    (another participant, as a leaked sim would be), and lasts 5 times as long as the slowest
    such discovery took on this machine (at least MIN_WINDOW_S); the other sim has been running
    since before the probe started, longer than the window.
    """
    import rclpy
    with reserve_any_domain() as a, reserve_any_domain() as b:
        assert a.domain_id != b.domain_id
        sims = [SimProcess(namespace, env=r.environment()) for r in (a, b)]
        contexts, probes = [], []
        try:
            for r in (a, b):
                context = rclpy.Context()
                rclpy.init(context=context, domain_id=r.domain_id)
                contexts.append(context)
                probes.append(rclpy.create_node('domain_probe', namespace=namespace,
                                                context=context))
            first = [wait_until(lambda p=probe: _camera_publishers(p), DISCOVERY_S,
                                f'the sim of domain {r.domain_id}, seen by its probe')
                     for r, probe in zip((a, b), probes, strict=True)]
            took = max(_control_discovery_s(r.domain_id, namespace, probe)
                       for r, probe in zip((a, b), probes, strict=True))
            window = _observe(probes, max(MIN_WINDOW_S, 5 * took))
            for head, rest in zip(first, window, strict=True):
                seen = [head, *rest]
                assert max(seen) == 1, f'camera publishers seen over time: {seen}'
                assert seen[-1] == 1
        finally:
            for probe in probes:
                probe.destroy_node()
            for context in contexts:
                rclpy.try_shutdown(context=context)
            for sim in sims:
                sim.stop()
