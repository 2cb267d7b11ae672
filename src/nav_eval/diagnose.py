"""Diagnose one failed evaluation episode layer by layer (the workshop's failure-layer model).

    ros2 run nav_eval diagnose RUN_DIR [--set dqn_heldout] [--seed N] [--no-rerun]

Reads the episode's trace and frames written by ``nav_eval evaluate`` (default: the first
failed episode of ``dqn_heldout``, else of ``dqn_train``), shows frames, actions, reward terms,
distance and Q-values per step, checks each layer's evidence
(:mod:`nav_eval.analysis.failure_layers`), re-runs the episode to test that evaluation is
deterministic, and names the earliest layer that looks broken or suspect.  Writes
``RUN_DIR/eval/diagnosis.{json,md}`` and its figures.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nav_eval.reporting.diagnosis_report import diagnose_run
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.training.timing import quiet_learner_threads


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-eval-diagnose`` command."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('run_dir', type=Path, help='training run directory (evaluated)')
    parser.add_argument('--set', dest='set_name', help='evaluation set (default: the first '
                        'failure of dqn_heldout, then dqn_train)')
    parser.add_argument('--seed', type=int, help='episode seed within the set')
    parser.add_argument('--no-rerun', action='store_true',
                        help='skip the determinism re-run of the episode')
    args = parser.parse_args(strip_ros_args(argv))
    quiet_learner_threads()  # the re-run's forward passes must not spin against the sim
    run_command('nav-eval-diagnose',
                lambda: diagnose_run(args.run_dir, args.set_name, args.seed,
                                     not args.no_rerun) and 0)


if __name__ == '__main__':
    main()
