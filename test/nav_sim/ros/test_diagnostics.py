"""The time budget of a control period on /diagnostics, and the rolling means behind it."""

from __future__ import annotations

import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from helpers import wait_until
from nav_sim.core.step_timing import REPORT_INTERVAL_S, StepTiming
from nav_sim.ros.client import SimClient
from nav_sim.ros.node import PERIOD_PHASES
from nav_sim.ros.process import SimProcess


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


#: the client's pause before each command: time the sim spends waiting for it
IDLE_S = 0.05


def test_sim_node_publishes_where_a_period_goes(namespace):
    name = f'{namespace}/sim_node: control period'
    reports: list[tuple[int, dict[str, float]]] = []  # (sim stamp, values) of each report
    stepped: dict[int, float] = {}  # stamp of each period the client stepped -> when it came

    def on_diagnostics(msg: DiagnosticArray) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        for status in msg.status:
            if status.name == name:
                reports.append((stamp_ns, {kv.key: float(kv.value) for kv in status.values}))

    with SimProcess(namespace, params={'publish_clock': False}) as sim, \
            SimClient(namespace, timeout=15.0) as client:
        client.node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        client.wait_for_sim(30.0, sim.failure)
        frame, _ = client.reset(seed=5, split='train')

        def two_reports() -> bool:
            nonlocal frame
            for i in range(20):  # resets between periods, as in training
                if i % 4:
                    time.sleep(IDLE_S)
                    frame = client.step(0.0, 0.3, frame)
                    stepped[frame.stamp_ns] = time.monotonic()
                else:
                    frame = client.reset(seed=5)[0]
            return client.spin_until(lambda: len(reports) >= 2, 0.05)

        # the first report may be lost to discovery and its window start mid-way: once one
        # arrived, the next is delivered, and it covers a whole window
        wait_until(two_reports, 60.0, 'two /diagnostics reports from the sim', interval=0)
    (previous_ns, _), (stamp_ns, report) = reports[-2], reports[-1]
    # a report goes right after the period it closes, stamped with that period's sim time:
    # its window holds exactly the steps after the previous report's (resets are no periods)
    window = [t for t in stepped if previous_ns < t <= stamp_ns]
    assert report['periods'] == len(window) >= 1
    # the window's wall time as the client saw it, frame to frame; the sim's measure differs
    # by the delivery delays of two frames (milliseconds; 0.25 s is the margin for a loaded
    # 2-core machine), while a window lasts at least the 1 s report interval
    seen_s = stepped[stamp_ns] - stepped[previous_ns]
    assert report['periods'] * report['period_ms'] / 1e3 == pytest.approx(seen_s, abs=0.25)
    # a report closes its window only once the report interval has passed (by the sim's
    # clock, from one report's period end to the next; 10 ms for the bookkeeping between)
    assert report['periods'] / report['periods_per_s'] >= REPORT_INTERVAL_S - 0.01
    # every phase the sim runs took time; the wait covers at least the client's pause (the
    # sim closes a period microseconds after publishing its frame: 20 % margin)
    assert all(report[f'{phase}_ms'] > 0 for phase in PERIOD_PHASES if phase != 'live')
    assert report['wait_ms'] >= 0.8 * 1e3 * IDLE_S
    assert report['live_ms'] == 0.0  # the live view is off
    accounted = sum(report[f'{phase}_ms'] for phase in PERIOD_PHASES)
    # the phases cover the period's wall time; the untimed rest is a few bookkeeping lines
    assert accounted == pytest.approx(report['period_ms'], rel=0.05, abs=0.05)
