"""The time budget of a control period on /diagnostics, and the rolling means behind it."""

from __future__ import annotations

import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from nav_sim.client import SimClient
from nav_sim.sim_node import PERIOD_PHASES
from nav_sim.sim_process import SimProcess
from nav_sim.step_timing import StepTiming


def test_step_timing_means_cover_exactly_the_closed_steps():
    timing = StepTiming(('a', 'b'), interval=1.0, unit='period')
    timing.add('a', 5.0)       # before the first close: dropped (no start reference)
    timing.step_done(now=10.0)
    for end in (10.5, 11.0, 11.5):
        timing.add('a', 0.1)
        timing.add('b', 0.3)
        timing.step_done(now=end)
    report = timing.report(now=11.5)
    assert report['periods'] == 3
    assert report['period_ms'] == pytest.approx(500.0)
    assert report['a_ms'] == pytest.approx(100.0) and report['b_ms'] == pytest.approx(300.0)
    assert report['periods_per_s'] == pytest.approx(2.0)
    timing.add('a', 0.2)
    timing.step_done(now=12.5)
    assert not timing.due(now=12.0)
    assert timing.due(now=12.6)
    second = timing.report(now=12.6)
    assert second['periods'] == 1 and second['period_ms'] == pytest.approx(1000.0)
    assert timing.totals()['a_ms'] == pytest.approx(1e3 * 0.5 / 4)


def test_sim_node_publishes_where_a_period_goes(namespace):
    name = f'{namespace}/sim_node: control period'
    reports: list[dict[str, float]] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == name:
                reports.append({kv.key: float(kv.value) for kv in status.values})

    with SimProcess(namespace, params={'publish_clock': False}) as sim, \
            SimClient(namespace, timeout=15.0) as client:
        client.node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        client.wait_for_sim(30.0, sim.failure)
        frame, _ = client.reset(seed=5, split='train')
        deadline = time.monotonic() + 60.0
        while len(reports) < 2:  # the first window may start mid-way; judge a whole one
            assert time.monotonic() < deadline, 'no /diagnostics from the sim within 60 s'
            for i in range(20):  # resets between periods, as in training
                frame = client.step(0.0, 0.3, frame) if i % 4 else client.reset(seed=5)[0]
            client.spin_until(lambda: len(reports) >= 2, 0.05)
    report = reports[-1]
    for phase in PERIOD_PHASES:
        assert report[f'{phase}_ms'] >= 0.0
    assert report['physics_ms'] > 0 and report['render_ms'] > 0 and report['wait_ms'] > 0
    assert report['live_ms'] == 0.0  # the live view is off
    assert report['periods'] >= 1
    assert report['periods_per_s'] == pytest.approx(1e3 / report['period_ms'], rel=0.02)
    accounted = sum(report[f'{phase}_ms'] for phase in PERIOD_PHASES)
    # the phases cover the period's wall time; the untimed rest is a few bookkeeping lines
    assert accounted == pytest.approx(report['period_ms'], rel=0.05, abs=0.05)
