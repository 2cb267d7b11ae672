"""Train and evaluate several seeds of one or more configurations on Ray Tune, then aggregate.

    ros2 run nav_eval sweep [--seeds 1-5] [--grid KEY=V1,V2 ...] [--set KEY=V ...]
                            [--total-timesteps N] [--cpus-per-trial C] [--gpus-per-trial 0]
                            [--address auto|HOST:PORT] [--storage DIR] [--name NAME]
    ros2 run nav_eval sweep --resume SWEEP_DIR      # continue an interrupted sweep
    ros2 run nav_eval sweep ... --summary DEST      # keep the summary form in DEST, per trial
    ros2 run nav_eval sweep --aggregate DIR         # statistics of finished trials only
    ros2 run nav_eval sweep --export SWEEP_DIR DEST # copy the summary form (for docs/sweeps)

What a sweep directory holds is :mod:`nav_eval.sweeps.spec`'s docstring.  Ray Tune schedules the
trials (one per seed and configuration, plus one baseline trial per configuration), places them
on the cluster's CPUs and GPUs, retries a failed trial once and restores an interrupted sweep.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nav_eval.seeds import CURVE, HELDOUT_BANK, TRAIN_BANK, add_many_episodes_argument, seed_text
from nav_eval.sweeps.cluster import check_cluster
from nav_eval.sweeps.runner import aggregate, export, run_sweep
from nav_eval.sweeps.spec import (
    check_summary,
    load_spec,
    new_sweep_id,
    save_spec,
    spec_from_args,
    summary_folder,
)
from nav_gym.cli import run_command, strip_ros_args


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``visnav-sweep``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    what = parser.add_mutually_exclusive_group()
    what.add_argument('--resume', type=Path, metavar='SWEEP_DIR',
                      help='continue an interrupted sweep (finished trials are not re-run)')
    what.add_argument('--aggregate', type=Path, metavar='DIR', help='only aggregate: a sweep '
                      'directory, or a directory of run directories (trials/ or its own)')
    what.add_argument('--export', type=Path, nargs=2, metavar=('SWEEP_DIR', 'DEST'),
                      help='copy the summary form of an aggregated sweep (Sweep.md, '
                      'results.json, sweep.json, figures/, configs/) to DEST, e.g. '
                      'docs/sweeps/NAME')
    parser.add_argument('--seeds', default='1-5', help='training seeds (default 1-5)')
    parser.add_argument('--grid', action='append', metavar='KEY=V1,V2',
                        help='a setting to vary (training or sim), repeatable: the grid is '
                        'every combination')
    parser.add_argument('--set', action='append', metavar='KEY=V',
                        help='a setting for every trial (training or sim), repeatable')
    parser.add_argument('--total-timesteps', type=int, help='training steps per trial')
    parser.add_argument('--train-seeds', default=seed_text(TRAIN_BANK),
                        help='training-bank scenarios of the final evaluation')
    parser.add_argument('--heldout-seeds', default=seed_text(HELDOUT_BANK),
                        help='held-out scenarios of the final evaluation')
    parser.add_argument('--curve-seeds', default=seed_text(CURVE), help="held-out scenarios per "
                        "checkpoint for the sample-efficiency curve ('' = none)")
    add_many_episodes_argument(parser)
    parser.add_argument('--no-baselines', action='store_true',
                        help='skip the random policy and servo on both banks')
    parser.add_argument('--record', action='store_true', help='write MCAP bags of the final '
                        'evaluation (large: 200 episodes per trial)')
    parser.add_argument('--cpus-per-trial', type=float, help='CPUs each trial gets (default '
                        '2, or n_envs + 1 where --set or --grid gives n_envs: a sim per env and '
                        'the learner)')
    parser.add_argument('--gpus-per-trial', type=float, default=0,
                        help='> 0: the trial trains on cuda')
    parser.add_argument('--address', help="attach to a Ray cluster ('auto' or HOST:PORT); "
                        'default: start Ray on this machine for the sweep')
    parser.add_argument('--storage', default='runs', help='directory of the sweep directory '
                        '(on a cluster: a path every node shares)')
    parser.add_argument('--name', help='sweep directory name (default sweep_<date>_<time>)')
    parser.add_argument('--summary', type=Path, metavar='DEST',
                        help="keep the sweep's summary form (what --export writes) in DEST, "
                        'rewritten after each finished trial, e.g. docs/sweeps/NAME: what has '
                        'finished outlives a checkout that does not keep runs/ (with --resume: '
                        'from now on)')
    parser.add_argument('--retry-failed', action='store_true',
                        help='with --resume: run failed trials again')
    return parser


def main(argv: list[str] | None = None) -> None:
    """Run ``visnav-sweep``."""
    args = build_parser().parse_args(strip_ros_args(argv))

    def body() -> int:
        if args.aggregate:
            aggregate(args.aggregate.resolve())
            return 0
        if args.export:
            print(f'sweep summary: {export(*args.export)}')
            return 0
        check_cluster(args.address)  # within seconds, before anything is written
        if args.resume:
            spec = load_spec(args.resume)
            if args.summary is not None:  # kept in sweep.json for the next --resume
                spec.sweep_id = spec.sweep_id or new_sweep_id()  # a sweep from before has none
                spec.summary = summary_folder(args.summary, spec)
                save_spec(spec)
            elif spec.summary:
                check_summary(Path(spec.summary), spec.sweep_id)
            if args.cpus_per_trial is not None:  # this session's only; else the sweep's own
                spec.cpus_per_trial = args.cpus_per_trial
            if args.gpus_per_trial != 0:
                spec.gpus_per_trial = args.gpus_per_trial
            return run_sweep(spec, args.address, resume=True, retry_failed=args.retry_failed)
        return run_sweep(spec_from_args(args), args.address, resume=False)

    run_command('visnav-sweep', body)


if __name__ == '__main__':
    sys.exit(main())
