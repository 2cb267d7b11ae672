"""Sim core in process vs. lockstep round trip through the nav_sim node, side by side.

    .venv/bin/python benchmarks/bench_sim.py [--periods 2000]

Both loops do the same work per control period: one wheel command for ``action_repeat`` physics
steps with goal/collision checks, then one camera render.  The ROS loop adds: publish
``cmd_vel`` -> sim node steps, renders, publishes image + event -> client receives both.
Target: the round trip reaches at least 60% of the in-process rate.

Also the CPU an idle lockstep sim uses (no client; target < 1 % of a core): its CPU time from
``/proc/PID/stat`` over ``--idle-seconds`` of idling.

And the floor of any lockstep through DDS (``--floor-trips``, 0 to skip): a bare round trip of a
``Twist`` each way between this process and a child (``--echo``), through bare rcl wait sets with
the client's QoS, no sim and no images.  The in-process period plus that round trip bounds the
ratio a lockstep client of a separate sim process could reach on this machine.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

from geometry_msgs.msg import Twist  # noqa: E402

from nav_sim.core.kinematics import twist_to_wheels  # noqa: E402
from nav_sim.core.sim import NavSim  # noqa: E402
from nav_sim.ros import qos  # noqa: E402
from nav_sim.ros.bare import own_node, subscription_wait_set, take, wait_ready  # noqa: E402
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


def _next(wait_set: object, subscription: object, timeout_s: float) -> Twist | None:
    """Wait on ``subscription`` alone, as the lockstep hot paths do; its message or None."""
    return take(subscription) if wait_ready(wait_set, [subscription], timeout_s) else None


def echo(namespace: str) -> None:
    """Send every ``ping`` back on ``pong`` (the floor's child); end on a negative ``linear.x``."""
    context, node = own_node('bench_echo', namespace)
    pong = node.create_publisher(Twist, 'pong', qos.OBSERVATION)
    ping = node.create_subscription(Twist, 'ping', lambda _: None, qos.CONTROL)
    waits = subscription_wait_set(context, 1)
    deadline = time.monotonic() + 300.0
    while time.monotonic() < deadline:
        message = _next(waits, ping, 0.2)
        if message is not None:
            pong.publish(message)
            if message.linear.x < 0:
                break
    context.try_shutdown()


def dds_floor(trips: int) -> float:
    """Median seconds of a bare ``Twist`` round trip to a child process and back."""
    namespace = f'/bench_floor_{os.getpid()}'
    context, node = own_node('bench_floor', namespace)
    ping = node.create_publisher(Twist, 'ping', qos.CONTROL)
    pong = node.create_subscription(Twist, 'pong', lambda _: None, qos.OBSERVATION)
    waits = subscription_wait_set(context, 1)
    child = subprocess.Popen([sys.executable, __file__, '--echo', namespace])
    try:
        deadline = time.monotonic() + 30.0
        while ping.get_subscription_count() == 0 or pong.get_publisher_count() == 0:
            if child.poll() is not None:
                raise SystemExit(f'bench_sim: the echo process ended (exit {child.returncode})')
            if time.monotonic() > deadline:
                raise SystemExit('bench_sim: the echo process did not connect within 30 s')
            time.sleep(0.05)
        message, times = Twist(), []
        for i in range(trips + 100):  # the first 100 warm up
            message.angular.z = float(i)
            start = time.perf_counter()
            ping.publish(message)
            while (answer := _next(waits, pong, 5.0)) is None or answer.angular.z != i:
                if answer is None and i >= 100:
                    raise SystemExit('bench_sim: no echo within 5 s')
                if answer is None:  # the echo's writer may not have matched us yet
                    ping.publish(message)
            times.append(time.perf_counter() - start)
        message.linear.x = -1.0
        ping.publish(message)
        child.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass  # the echo did not take the last message: killed below
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        context.try_shutdown()
    return sorted(times[100:])[trips // 2]


def main() -> None:
    """Measure both rates in alternating runs, then the idle sim's CPU; print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--periods', type=int, default=2000)
    parser.add_argument('--repeats', type=int, default=3, help='alternating runs; best kept')
    parser.add_argument('--idle-seconds', type=float, default=5.0,
                        help='how long the idle sim is measured')
    parser.add_argument('--floor-trips', type=int, default=2000,
                        help='round trips of the DDS floor per run (0: skip it)')
    parser.add_argument('--echo', metavar='NAMESPACE', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.floor_trips < 0:
        parser.error(f'--floor-trips must be 0 or more, got {args.floor_trips}')
    if args.echo:
        echo(args.echo)
        return
    core, ros, floor = [], [], []
    for _ in range(args.repeats):
        core.append(in_process(args.periods))
        ros.append(through_ros(args.periods))
        if args.floor_trips:
            floor.append(dds_floor(args.floor_trips))
    best_core, best_ros = max(core), max(ros)
    print(f'control periods/s, {args.periods} periods, best of {args.repeats} alternating runs')
    print(f'  sim core in process (step + render):    {best_core:8.0f} /s  '
          f'({1e3 / best_core:.3f} ms)  runs: {[round(v) for v in core]}')
    print(f'  lockstep round trip through nav_sim:    {best_ros:8.0f} /s  '
          f'({1e3 / best_ros:.3f} ms)  runs: {[round(v) for v in ros]}')
    ratio = best_ros / best_core
    print(f'  ratio round trip / in process:          {ratio:8.1%}  (target >= 60%: '
          f"{'met' if ratio >= 0.6 else 'NOT met'})")
    if floor:
        best_floor = min(floor)
        ceiling = (1 / best_core) / (1 / best_core + best_floor)
        print(f'  DDS floor: a bare Twist round trip:     {best_floor * 1e6:8.0f} us median  '
              f'runs: {[round(v * 1e6) for v in floor]}')
        print(f'  lockstep ceiling with that floor alone: {ceiling:8.1%}  (in-process period + '
              'the floor; no image, no event)')
    idle = idle_cpu(args.idle_seconds)
    print(f'  idle lockstep sim, no client:           {idle:8.2%} of a core over '
          f"{args.idle_seconds:g} s  (target < 1%: {'met' if idle < 0.01 else 'NOT met'})")


if __name__ == '__main__':
    main()
