"""Start the sim node as ``ros2 run nav_sim sim_node`` would and drive one scripted episode.

    nav-sim-demo [--seed 101] [--split train] [--namespace /visnav_demo] [--live [PORT]]

Prints the scenario, then each control period: command, wheel speeds, pose, distance and event.
With ``--live`` the sim node serves its Foxglove live view (``live_port``) and the episode runs
at wall-clock pace (one control period per ``ctrl_dt``), so it can be watched.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from nav_sim.core.config import TRAIN, SimConfig
from nav_sim.core.scenarios import DEMO_SEED
from nav_sim.errors import NavSimError
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import SimProcess
from nav_sim.viz.options import add_live_argument

FORWARD, LEFT, RIGHT = (0.12, 0.0), (0.0, 1.5), (0.0, -1.5)
SCRIPT = [('forward', FORWARD)] * 6 + [('left', LEFT)] * 4 + [('forward', FORWARD)] * 6 + \
    [('right', RIGHT)] * 4 + [('forward', FORWARD)] * 60


def run(seed: int, split: str, namespace: str, live_port: int = 0) -> int:
    """Drive the scripted episode; returns a process exit code."""
    print(f'starting sim_node in namespace {namespace} ...', flush=True)
    params = {'publish_clock': False, 'live_port': live_port}
    pace = SimConfig().ctrl_dt if live_port else 0.0
    if live_port:
        print(f'live view: open ws://localhost:{live_port} in Foxglove (layout: '
              'config/foxglove/visnav.json); the episode runs at wall-clock pace', flush=True)
    with SimProcess(namespace=namespace, params=params) as sim, \
            SimClient(namespace, timeout=20.0, node_name='visnav_demo') as client:
        client.wait_for_sim(abort=sim.failure, started=sim.ready)
        frame, scenario = client.reset(seed=seed, split=split)
        print(f"scenario: seed={scenario['seed']} split={scenario['split']} "
              f"layout={scenario['layout']} start={scenario['start']} goal={scenario['goal']} "
              f"initial_distance={scenario['initial_distance']:.3f} m")
        print(f'camera: {frame.image.width}x{frame.image.height} {frame.image.encoding}')
        print(f"{'step':>4} {'command':>8} {'wheel L':>8} {'wheel R':>8} {'x':>7} {'y':>7} "
              f"{'yaw':>7} {'dist':>6} event")
        for name, (linear, angular) in SCRIPT:
            time.sleep(pace)
            frame = client.step(linear, angular, frame)
            e = frame.event
            print(f"{e['episode_step']:>4} {name:>8} {e['wheel_left']:>8.2f} "
                  f"{e['wheel_right']:>8.2f} {frame.pose[0]:>7.3f} {frame.pose[1]:>7.3f} "
                  f"{frame.pose[2]:>7.3f} {e['distance']:>6.3f} {e['event']}")
            if e['done']:
                break
        wheels = client.stop()
        outcome = frame.event['event'] if frame.event['done'] else 'script ended'
        print(f'episode over: {outcome}; motors stopped, wheel speeds {wheels}')
    print(f'sim_node exited with code {sim.process.returncode}')
    return 0 if sim.process.returncode == 0 else 1


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-sim-demo`` command."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seed', type=int, default=DEMO_SEED)
    parser.add_argument('--split', default=TRAIN)
    parser.add_argument('--namespace', default=f'/visnav_demo_{os.getpid()}')
    add_live_argument(parser, "the sim node's Foxglove live view", ' and run at wall-clock pace')
    args = parser.parse_args(argv)
    try:
        sys.exit(run(args.seed, args.split, args.namespace, args.live))
    except NavSimError as exc:
        print(f'nav-sim-demo: {exc}', file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:
        sys.exit(130)


if __name__ == '__main__':
    main()
