"""Run the scripted baselines on both scenario banks and write them as JSON.

    python -m nav_eval.baselines [--config FILE] [--sim-params '{...}'] [--train-seeds 101-200]
                                 [--heldout-seeds 201-300] [--out baselines.json]

The uniform-random policy and the image-only servo, through the environment of a training
config (:mod:`nav_eval.evaluation.baselines`); a sweep runs this for each configuration.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from nav_eval.evaluation.baselines import BASELINE_POLICIES, run_baselines
from nav_eval.seeds import (
    HELDOUT_BANK,
    TRAIN_BANK,
    add_many_episodes_argument,
    check_episodes,
    parse_seeds,
    seed_text,
)
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.training.config import build
from nav_gym.training.timing import quiet_learner_threads


def main(argv: list[str] | None = None) -> None:
    """Run the baselines from the command line and write them as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='training config YAML (default: the defaults)')
    parser.add_argument('--sim-params', help="sim settings as JSON/YAML, e.g. '{\"x\": 1}'")
    parser.add_argument('--train-seeds', default=seed_text(TRAIN_BANK))
    parser.add_argument('--heldout-seeds', default=seed_text(HELDOUT_BANK))
    parser.add_argument('--policies', default=','.join(BASELINE_POLICIES))
    parser.add_argument('--out', type=Path, default=Path('baselines.json'))
    add_many_episodes_argument(parser)
    args = parser.parse_args(strip_ros_args(argv))
    quiet_learner_threads()

    def body() -> int:
        train, heldout = parse_seeds(args.train_seeds), parse_seeds(args.heldout_seeds)
        policies = tuple(p for p in args.policies.split(',') if p)
        check_episodes((len(train) + len(heldout)) * len(policies), args.many_episodes)
        overrides = {'sim_params': args.sim_params} if args.sim_params else {}
        config = build(args.config, overrides).with_full_sim_params()
        start = time.perf_counter()
        result = run_baselines(config, train, heldout, policies, progress=True)
        args.out.write_text(json.dumps(result, indent=1))
        print(f'baselines in {time.perf_counter() - start:.0f} s -> {args.out}')
        return 0

    run_command('nav-eval-baselines', body)


if __name__ == '__main__':
    main()
