"""Training wall-clock with N parallel sims (``n_envs``), measured side by side in one run.

    .venv/bin/python benchmarks/bench_envs.py [--n-envs 1,2] [--steps 6000] [--repeats 1]
        [--device cpu] [--json FILE] [-- extra nav-gym-train flags]

Each run is a whole ``nav-gym-train`` (its own process, sims started by the envs) with the
default learner and settings, except ``--total-timesteps``; checkpoints and the replay buffer
are not saved.  The figure is the training wall-clock in the run's summary.json (building the
envs and the model, then learning), and the ratio of each N's steps/s to N = 1's.  Repeats
alternate the N values, so that a change in the machine's load hits them all alike.

Targets (issue 29): on the 2-core machine kind, ``n_envs: 2`` no slower than 1 (ratio >= 1.0);
on a GPU machine, a 50k-step run with ``n_envs: 8`` on cuda in at most 90 s
(``--n-envs 8 --steps 50000 --device cuda``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

#: nav-gym-train, run by this interpreter (also where the package is on PYTHONPATH only)
TRAIN = [sys.executable, '-m', 'nav_gym.train']


def train_once(n_envs: int, steps: int, device: str, runs_dir: Path, name: str,
               extra: list[str]) -> dict:
    """Train one run and return its summary.json (raises with the output on a failure)."""
    command = [*TRAIN, '--total-timesteps', str(steps), '--n-envs', str(n_envs),
               '--device', device, '--runs-dir', str(runs_dir), '--run-name', name,
               '--checkpoint-freq', str(10 * steps), '--save-replay-buffer', 'false', *extra]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f'n_envs {n_envs} failed:\n{result.stdout}\n{result.stderr}')
    return json.loads((runs_dir / name / 'summary.json').read_text())


def main() -> None:
    """Train each N, alternating, and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n-envs', default='1,2', help='comma-separated N values (default 1,2)')
    parser.add_argument('--steps', type=int, default=6000, help='environment steps per run')
    parser.add_argument('--repeats', type=int, default=1, help='runs per N, alternating')
    parser.add_argument('--device', default='cpu', help="torch device ('cpu', 'cuda')")
    parser.add_argument('--json', help='also write the table as JSON to this file')
    parser.add_argument('extra', nargs='*', help='more nav-gym-train flags (after --)')
    args = parser.parse_args()
    values = [int(v) for v in args.n_envs.split(',')]
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    runs: dict[int, list[dict]] = {n: [] for n in values}
    with tempfile.TemporaryDirectory(prefix='bench_envs_') as tmp:
        for repeat in range(args.repeats):
            for n in values:
                summary = train_once(n, args.steps, args.device, Path(tmp), f'n{n}_{repeat}',
                                     args.extra)
                runs[n].append(summary)
                print(f"n_envs {n} run {repeat + 1}: {summary['wall_clock_s']:.1f} s "
                      f"({summary['steps_per_s']:.1f} steps/s)", flush=True)
    base = statistics.median(s['steps_per_s'] for s in runs[values[0]])
    rows = []
    for n in values:
        rate = statistics.median(s['steps_per_s'] for s in runs[n])
        budget = runs[n][0]['time_budget']['env_step']
        rows.append({'n_envs': n, 'steps': args.steps, 'device': args.device,
                     'wall_clock_s': statistics.median(s['wall_clock_s'] for s in runs[n]),
                     'steps_per_s': rate, 'ratio': round(rate / base, 3),
                     'env_share': statistics.median(s['env_share'] for s in runs[n]),
                     'gradient_step_ms': budget.get('gradient_step_ms'),
                     'vector_step_ms': budget.get('step_ms')})
    print(f"\n{'n_envs':>6} {'wall s':>8} {'steps/s':>8} {'ratio':>6} {'env share':>9} "
          f"{'grad ms':>8} {'vec step ms':>11}")
    for row in rows:
        print(f"{row['n_envs']:>6} {row['wall_clock_s']:>8.1f} {row['steps_per_s']:>8.1f} "
              f"{row['ratio']:>6.2f} {row['env_share']:>9.1%} {row['gradient_step_ms']:>8.2f} "
              f"{row['vector_step_ms']:>11.2f}")
    print(f'(ratio: steps/s against n_envs {values[0]}, medians of {args.repeats} run(s); '
          f'{os.cpu_count()} CPUs, device {args.device})')
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))


if __name__ == '__main__':
    main()
