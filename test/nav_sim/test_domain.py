"""Host-local ROS domain reservations: unique while held, freed on release, isolating sims."""

from __future__ import annotations

import random
import subprocess
import sys
import time

import pytest

from nav_sim.domain import (
    DomainUnavailableError,
    reserve_any_domain,
    reserve_domain,
)
from nav_sim.sim_process import SimProcess

DISCOVERY_S = 60.0


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
        code = ('import sys; from nav_sim.domain import reserve_domain, DomainUnavailableError\n'
                f'try:\n    reserve_domain([{mine.domain_id}])\n'
                'except DomainUnavailableError:\n    sys.exit(3)\n')
        assert subprocess.run([sys.executable, '-c', code], timeout=60).returncode == 3
        env = mine.environment({})
        assert env == {'ROS_DOMAIN_ID': str(mine.domain_id),
                       'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}


def _counts(context, namespace: str) -> list[int]:
    """Camera publishers in ``namespace`` as seen from a node in ``context``."""
    import rclpy
    node = rclpy.create_node('domain_probe', namespace=namespace, context=context)
    try:
        seen = []
        deadline = time.monotonic() + DISCOVERY_S
        while time.monotonic() < deadline:
            seen.append(node.count_publishers(node.resolve_topic_name('camera/image_raw')))
            if seen[-1] >= 1:
                break
            time.sleep(0.1)
        # both sims are up by now: a second publisher would be discovered within this window
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            seen.append(node.count_publishers(node.resolve_topic_name('camera/image_raw')))
            time.sleep(0.1)
        return seen
    finally:
        node.destroy_node()


def test_two_sims_in_one_namespace_but_different_domains_do_not_see_each_other(namespace):
    import rclpy
    with reserve_any_domain() as a, reserve_any_domain() as b:
        assert a.domain_id != b.domain_id
        sims = [SimProcess(namespace, env=r.environment()) for r in (a, b)]
        contexts = []
        try:
            for r in (a, b):
                context = rclpy.Context()
                rclpy.init(context=context, domain_id=r.domain_id)
                contexts.append(context)
            for context in contexts:
                seen = _counts(context, namespace)
                assert max(seen) == 1, f'camera publishers seen over time: {seen}'
                assert seen[-1] == 1
        finally:
            for context in contexts:
                rclpy.try_shutdown(context=context)
            for sim in sims:
                sim.stop()
