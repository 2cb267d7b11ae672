"""Train and evaluate one sweep trial (its JSON as the argument): a sweep trial's child.

    python -m nav_eval.sweep_trial TRIAL_JSON

Runs :func:`nav_eval.sweeps.trial.train_and_evaluate` with ``nav-gym-train``'s signal handling
(SIGTERM stops training or evaluation as Ctrl-C does, with cleanup).
"""

from __future__ import annotations

import json
import sys

from nav_eval.sweeps.trial import train_and_evaluate
from nav_gym.cli import run_command, stop_on_sigterm
from nav_gym.training.timing import quiet_learner_threads


def main(argv: list[str] | None = None) -> None:
    """Train and evaluate the trial whose JSON is the first argument."""
    args = sys.argv[1:] if argv is None else argv
    quiet_learner_threads()  # before torch: the policy's forward passes must not spin
    # SIGTERM (the Ray worker died) stops training or evaluation as Ctrl-C does, with cleanup
    stop_on_sigterm()
    run_command('nav_eval.sweep_trial', lambda: train_and_evaluate(json.loads(args[0])))


if __name__ == '__main__':
    main()
