"""Sim core in process vs. lockstep round trip through the nav_sim node, side by side.

    .venv/bin/python benchmarks/bench_sim.py [--periods 2000]

Both loops do the same work per control period: one wheel command for ``action_repeat`` physics
steps with goal/collision checks, then one camera render.  The ROS loop adds: publish
``cmd_vel`` -> sim node steps, renders, publishes image + event -> client receives both.
Target: the round trip reaches at least 60% of the in-process rate.

Also the CPU an idle lockstep sim uses (no client; target < 1 % of a core): its CPU time from
``/proc/PID/stat`` over ``--idle-seconds`` of idling.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

from nav_sim.core.kinematics import twist_to_wheels
from nav_sim.core.sim import NavSim  # noqa: E402
from nav_sim.ros.client import SimClient  # noqa: E402
from nav_sim.ros.process import SimProcess  # noqa: E402

TURN = (0.0, 1.0)  # turning in place: the episode never ends, every period does full work


def in_process(periods: int) -> float:
    """Control periods per second of the sim core stepped and rendered in this process."""
    sim = NavSim()
    try:
        sim.reset(101, 'train')
        command = twist_to_wheels(*TURN, sim.config)
        for _ in range(50):
            sim.step(command)
            sim.render()
        start = time.perf_counter()
        for _ in range(periods):
            sim.step(command)
            sim.render()
        return periods / (time.perf_counter() - start)
    finally:
        sim.close()


def through_ros(periods: int) -> float:
    """Control periods per second of lockstep round trips through a sim_node process."""
    namespace = f'/bench_{os.getpid()}'
    with SimProcess(namespace=namespace, params={'publish_clock': False}), \
            SimClient(namespace, timeout=30.0, node_name='bench_client') as client:
        client.wait_for_sim()
        frame, _ = client.reset(seed=101, split='train')
        for _ in range(50):
            frame = client.step(*TURN, frame)
        start = time.perf_counter()
        for _ in range(periods):
            frame = client.step(*TURN, frame)
        return periods / (time.perf_counter() - start)


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux ``/proc/PID/stat``)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def idle_cpu(seconds: float) -> float:
    """Share of a core a lockstep sim with no client uses over ``seconds``."""
    namespace = f'/bench_idle_{os.getpid()}'
    with SimProcess(namespace=namespace, params={'publish_clock': False}) as sim:
        with SimClient(namespace, timeout=30.0, node_name='bench_idle_client') as client:
            client.wait_for_sim(abort=sim.failure, started=sim.ready)
        before, start = cpu_seconds(sim.process.pid), time.monotonic()
        time.sleep(seconds)
        return (cpu_seconds(sim.process.pid) - before) / (time.monotonic() - start)


def main() -> None:
    """Measure both rates in alternating runs, then the idle sim's CPU; print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--periods', type=int, default=2000)
    parser.add_argument('--repeats', type=int, default=3, help='alternating runs; best kept')
    parser.add_argument('--idle-seconds', type=float, default=5.0,
                        help='how long the idle sim is measured')
    args = parser.parse_args()
    core, ros = [], []
    for _ in range(args.repeats):
        core.append(in_process(args.periods))
        ros.append(through_ros(args.periods))
    best_core, best_ros = max(core), max(ros)
    print(f'control periods/s, {args.periods} periods, best of {args.repeats} alternating runs')
    print(f'  sim core in process (step + render):    {best_core:8.0f} /s  '
          f'({1e3 / best_core:.3f} ms)  runs: {[round(v) for v in core]}')
    print(f'  lockstep round trip through nav_sim:    {best_ros:8.0f} /s  '
          f'({1e3 / best_ros:.3f} ms)  runs: {[round(v) for v in ros]}')
    ratio = best_ros / best_core
    print(f'  ratio round trip / in process:          {ratio:8.1%}  (target >= 60%: '
          f"{'met' if ratio >= 0.6 else 'NOT met'})")
    idle = idle_cpu(args.idle_seconds)
    print(f'  idle lockstep sim, no client:           {idle:8.2%} of a core over '
          f"{args.idle_seconds:g} s  (target < 1%: {'met' if idle < 0.01 else 'NOT met'})")


if __name__ == '__main__':
    main()
