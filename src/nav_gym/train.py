"""``ros2 run nav_gym train`` (and ``nav-gym-train``): train the learner on the sim, with resume.

    ros2 run nav_gym train [--config config/train.yaml] [--total-timesteps N] [...]
    nav-gym-train --resume runs/dqn_20261122_101500

A run directory holds: ``config.yaml`` (effective settings), ``monitor.csv``, ``tb/``
(TensorBoard), ``checkpoints/dqn_<steps>_steps.zip`` (every ``checkpoint_freq`` steps, all kept,
written atomically) with the replay buffer of the latest one (only while it serves resume),
``final_model.zip`` and ``summary.json`` (wall-clock time, steps/s, the environment's share of
the time).

At the end of training the final model and the summary are written first, then the last
checkpoint; the replay buffer is then deleted (``--keep-replay-buffer true`` keeps it).  Ctrl-C
at any moment, a sim that dies and a full disk all leave a resumable run (every file is
written to a temporary file and renamed; a temporary file is removed on every error) and say
how to resume.
"""

from __future__ import annotations

from nav_gym.cli import run_command, stop_on_sigterm, strip_ros_args
from nav_gym.training.timing import quiet_learner_threads
from nav_gym.training.trainer import command_parser, run_training


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-gym-train`` command."""
    args = command_parser(__doc__.splitlines()[0]).parse_args(strip_ros_args(argv))
    stop_on_sigterm()
    quiet_learner_threads()
    run_command('nav-gym-train', lambda: run_training(args))


if __name__ == '__main__':
    main()
