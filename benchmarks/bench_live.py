"""Measure what the Foxglove live view costs the env, three ways side by side in one run.

Env steps/s with the live view off, on with nobody connected, and on with one viewer subscribed
to every channel.

    .venv/bin/python benchmarks/bench_live.py [--steps 600] [--rounds 3] [--port 18765]

One env (its own sim child) runs the same seeded random actions in every segment; the three
modes alternate round by round (off, on without a viewer, on with a viewer) so that drift in the
machine's load spreads over all three.  The viewer is ``python -m nav_sim.viz.client``, a
headless WebSocket client in its own process (as Foxglove would be), subscribed to everything.
Target: with a viewer, env steps at most 5 % slower than with the live view off.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

import numpy as np  # noqa: E402

from nav_gym.env.config import EnvConfig  # noqa: E402
from nav_gym.env.navigation import NavigationEnv  # noqa: E402
from nav_sim.viz import topics as live_topics  # noqa: E402

MODES = ('off', 'on, no viewer', 'on, 1 viewer (all topics)')


def run_steps(env: NavigationEnv, actions: np.ndarray, seed: int
              ) -> tuple[float, float, float, float]:
    """Return four figures per step over ``actions``.

    Steps/s; ms per step spent in the live view (its wall time inside ``env.step``); CPU ms per
    step of this process's main thread and of its other threads (the live view's server among
    them).  Resets at episode ends count in all four.
    """
    env.reset(seed=seed)
    live = env.timing.total_seconds('live')
    start, cpu, main = time.perf_counter(), time.process_time(), time.thread_time()
    for i, action in enumerate(actions):
        _, _, terminated, truncated, _ = env.step(int(action))
        if terminated or truncated:
            env.reset(seed=seed + i)
    wall, main = time.perf_counter() - start, time.thread_time() - main
    cpu = time.process_time() - cpu
    live = env.timing.total_seconds('live') - live
    n = len(actions)
    return n / wall, 1e3 * live / n, 1e3 * main / n, 1e3 * (cpu - main) / n


def start_viewer(port: int, env: NavigationEnv, timeout: float = 30.0) -> subprocess.Popen:
    """Start a headless viewer subscribed to every channel; return once the server sees it."""
    viewer = subprocess.Popen([sys.executable, '-m', 'nav_sim.viz.client', '--port', str(port)],
                              stdout=subprocess.PIPE, text=True)
    deadline = time.monotonic() + timeout
    view = env.live.view
    while not all(view.wanted(t) for t in live_topics.ENV_TOPICS):
        if viewer.poll() is not None or time.monotonic() > deadline:
            viewer.kill()
            raise SystemExit(f'the viewer did not subscribe within {timeout} s')
        time.sleep(0.05)
    return viewer


def stop_viewer(viewer: subprocess.Popen) -> str:
    """Stop the viewer; return its last output line (messages received per topic)."""
    viewer.terminate()
    out, _ = viewer.communicate(timeout=15)
    return out.strip().splitlines()[-1] if out.strip() else '{}'


def main() -> None:
    """Print steps/s of the three modes and the slowdowns against 'off'."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--steps', type=int, default=600, help='env steps per segment')
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--port', type=int, default=18765)
    args = parser.parse_args()
    actions = np.random.default_rng(0).integers(0, 3, size=args.steps)
    env = NavigationEnv(EnvConfig(sim='embedded'))
    results: dict[str, list[tuple[float, float, float, float]]] = {m: [] for m in MODES}
    received = ''
    try:
        env.start_live(args.port)
        live = env.live
        run_steps(env, actions[:100], 1)  # warm-up
        for r in range(args.rounds):
            env.observers.remove(live)  # as with the live view off: no observer at all
            results[MODES[0]].append(run_steps(env, actions, 1))
            env.observers.append(live)
            results[MODES[1]].append(run_steps(env, actions, 1))
            viewer = start_viewer(args.port, env)
            try:
                results[MODES[2]].append(run_steps(env, actions, 1))
            finally:
                received = stop_viewer(viewer)
            print(f'round {r + 1}: ' + ', '.join(f'{m}: {v[-1][0]:.0f} steps/s' for m, v in
                                                 results.items()), flush=True)
    finally:
        env.close()
    from nav_sim.viz.server import MAX_RATE_HZ
    rates = ', '.join(f'{t} {hz:.0f}/s' for t, hz in MAX_RATE_HZ.items())
    print(f'\nmedians of {args.rounds} rounds x {args.steps} steps; at most {rates}')
    print(f"  {'mode':<28} {'steps/s':>8} {'time/step':>10} {'in live view':>13} "
          f"{'main CPU':>9} {'other CPU':>10}  (ms per step)")
    base = float(np.median([v[0] for v in results[MODES[0]]]))
    for mode, values in results.items():
        rate, live, main, other = (float(np.median([v[k] for v in values])) for k in range(4))
        print(f'  {mode:<28} {rate:8.1f} {100 * (base / rate - 1):+9.1f}% {live:13.3f} '
              f'{main:9.3f} {other:10.3f}')
    watched = results[MODES[2]]
    live = float(np.median([v[1] for v in watched]))
    other = float(np.median([v[3] for v in watched])) - float(np.median(
        [v[3] for v in results[MODES[0]]]))
    share = 100 * (live + max(other, 0.0)) * base / 1e3
    print(f'  with a viewer, the live view adds {live:.3f} ms per step in env.step and '
          f'{other:+.3f} ms of CPU in other threads: {share:.1f} % of the off-mode step time')
    print(f'messages the viewer received in its last segment: {received}')


if __name__ == '__main__':
    main()
