"""The sweep's overhead: the same trials through ``visnav-sweep`` and as plain commands.

Measured side by side in one run.

    .venv/bin/python benchmarks/bench_sweep.py [--steps 2000] [--seeds 1,2] [--repeats 1]

Plain: for each seed, ``nav-gym-train`` then ``nav-eval-evaluate`` of the final model on
training seeds 101-110 and held-out seeds 201-210, one after another.  Sweep: the same trials
through ``visnav-sweep`` (Ray started and shut down, Tune's scheduling, a reserved ROS domain
per trial, aggregation with rliable), one trial at a time (``--cpus-per-trial`` = all CPUs), no
sample-efficiency curve and no baselines, so both sides do the same training and evaluation.
Overhead = sweep wall-clock / plain wall-clock - 1; target <= 10 %.  The time of the sweep's
statistics alone (``--aggregate`` run again on the same trials) is printed too, and the
overhead without it.  Both run in child
processes as a user would start them; with ``--repeats`` > 1 the order alternates.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EVAL = ['--train-seeds', '101-110', '--heldout-seeds', '201-210']
TRAIN = ['--checkpoint-freq', '1000000']  # no checkpoints but step 0 and the end: no curve
AGGREGATION: list[float] = []


def run(command: list[str], env: dict[str, str], show: bool = False) -> float:
    """Run a command to completion; return its wall-clock seconds (raise if it fails).

    ``show``: print its progress lines (``[HH:MM:SS] ...``: the sweep's trial starts and ends).
    """
    start = time.perf_counter()
    result = subprocess.run(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    if result.returncode != 0:
        raise SystemExit(f'{" ".join(command[:4])} failed:\n{result.stdout[-3000:]}')
    if show:
        for line in result.stdout.splitlines():
            if line.startswith('['):
                print(f'    {line}', flush=True)
    return time.perf_counter() - start


def plain(folder: Path, steps: int, seeds: list[int], env: dict[str, str]) -> float:
    """Train and evaluate each seed with the plain commands, one after another."""
    total = 0.0
    for seed in seeds:
        name = f'seed{seed}'
        train = run([sys.executable, '-m', 'nav_gym.train', '--total-timesteps', str(steps),
                     '--seed', str(seed), '--runs-dir', str(folder), '--run-name', name,
                     '--device', 'cpu', *TRAIN], env)
        evaluate = run([sys.executable, '-m', 'nav_eval.evaluate', str(folder / name), '--sets',
                        'dqn_train,dqn_heldout', *EVAL, '--no-record'], env)
        print(f'    {name}: train {train:.1f} s, evaluate {evaluate:.1f} s', flush=True)
        total += train + evaluate
    return total


def swept(folder: Path, steps: int, seeds: list[int], env: dict[str, str]) -> float:
    """Run the same trials as one sweep (Ray start to report)."""
    command = [sys.executable, '-m', 'nav_eval.sweep', '--seeds', ','.join(map(str, seeds)),
               '--total-timesteps', str(steps), '--set', 'checkpoint_freq=1000000', *EVAL,
               '--curve-seeds', '', '--no-baselines', '--cpus-per-trial', str(os.cpu_count()),
               '--storage', str(folder), '--name', 'sweep']
    seconds = run(command, env, show=True)
    for log in sorted((folder / 'sweep' / 'logs').glob('*.log')):  # the trial's child
        times = {('training' if line.startswith('# training') else 'whole child'):
                 line.split(' after ')[-1] for line in log.read_text().splitlines()
                 if line.startswith(('# training exited', '# exit code'))}
        print(f"    {log.stem}: {', '.join(f'{k} {v}' for k, v in times.items())}", flush=True)
    # the statistics alone, on the same trials (the plain commands compute none)
    AGGREGATION.append(run([sys.executable, '-m', 'nav_eval.sweep', '--aggregate',
                            str(folder / 'sweep')], env))
    return seconds


def main() -> None:
    """Print plain and sweep wall-clock times and the sweep's overhead."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--steps', type=int, default=2000)
    parser.add_argument('--seeds', default='1,2')
    parser.add_argument('--repeats', type=int, default=1)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(',')]
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    env.setdefault('MUJOCO_GL', 'egl')
    times: dict[str, list[float]] = {'plain': [], 'sweep': []}
    for repeat in range(args.repeats):
        order = ('plain', 'sweep') if repeat % 2 == 0 else ('sweep', 'plain')
        for kind in order:
            with tempfile.TemporaryDirectory(prefix=f'bench_sweep_{kind}_') as tmp:
                seconds = (plain if kind == 'plain' else swept)(Path(tmp), args.steps, seeds,
                                                                env)
            times[kind].append(seconds)
            print(f'{kind:<5} repeat {repeat + 1}: {seconds:7.1f} s', flush=True)
    mean = {k: sum(v) / len(v) for k, v in times.items()}
    overhead = mean['sweep'] / mean['plain'] - 1
    aggregation = sum(AGGREGATION) / len(AGGREGATION)
    scheduling = (mean['sweep'] - aggregation) / mean['plain'] - 1
    print(f'\n{len(seeds)} trials of {args.steps} steps + evaluation on 10 + 10 scenarios, '
          f'{os.cpu_count()} CPUs')
    print(f"plain commands, one after another: {mean['plain']:7.1f} s")
    print(f"visnav-sweep (Ray Tune):           {mean['sweep']:7.1f} s")
    print(f'  of which the statistics (visnav-sweep --aggregate, rerun): {aggregation:5.1f} s')
    print(f'overhead: {overhead:+.1%} (target <= +10%); without the statistics: '
          f'{scheduling:+.1%}')


if __name__ == '__main__':
    main()
