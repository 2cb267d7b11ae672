"""The main job: validate the environment -> train -> evaluate -> diagnose -> report.

    visnav-pipeline [--config config/train.yaml] [--run-name NAME] [any nav-gym-train flag]
    visnav-pipeline --resume runs/NAME      # finish an interrupted pipeline

Everything lands in one run directory: ``validation.json``, the training files (see
``nav_gym.train``), ``eval/`` (results, traces, MCAP bags, diagnosis) and ``report/Result.md`` +
``Result.html``.  Training is not started if a validation check fails.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict
from pathlib import Path

from nav_eval.errors import DiagnosisError
from nav_eval.evaluation.runner import evaluate, results_markdown
from nav_eval.evaluation.sets import DEFAULT_SETS, plan_sets
from nav_eval.reporting.diagnosis_report import diagnose_run
from nav_eval.reporting.run_report import write_report
from nav_eval.seeds import WORKSHOP_HELDOUT, WORKSHOP_TRAIN
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.env.checks import format_checklist, run_checklist, write_checklist
from nav_gym.env.config import EnvConfig
from nav_gym.env.navigation import NavigationEnv
from nav_gym.training import config as train_config
from nav_gym.training.config import TrainConfig
from nav_gym.training.files import write_text
from nav_gym.training.run_dir import CONFIG, FINAL_MODEL, VALIDATION, checkpoints
from nav_gym.training.timing import quiet_learner_threads
from nav_gym.training.trainer import config_and_run_dir, train
from nav_sim.viz.options import add_live_argument

STAGES = ('validate the environment', 'train the DQN', 'evaluate on fixed seeds',
          'diagnose a failed episode', 'write the report')
EXPERIMENTS_LOG = Path('docs/experiments.md')
VALIDATION_STEPS = 100


def stage(number: int) -> None:
    """Print the heading of a stage."""
    print(f'\n[{number}/{len(STAGES)}] {STAGES[number - 1]}', flush=True)


def validate_run(config: TrainConfig, run_dir: Path) -> bool:
    """Run the workshop's validation checklist on the run's environment (validation.json).

    Episodes get at least VALIDATION_STEPS so the scripted drivers can reach the goal and a
    wall whatever the run's time limit (the time-limit check uses its own 5-step env).
    """
    env_config = EnvConfig(**{**asdict(config.env_config()), 'sim': 'embedded',
                              'namespace': '', 'max_episode_steps':
                              max(config.max_episode_steps, VALIDATION_STEPS)})
    env = NavigationEnv(env_config)
    try:
        checks = run_checklist(env, lambda **kw: NavigationEnv(env_config, **kw))
    finally:
        env.close()
    print(format_checklist(checks), flush=True)
    write_checklist(checks, run_dir / VALIDATION)
    return all(c.passed for c in checks)


def run_pipeline(config: TrainConfig, run_dir: Path, resume: bool,
                 experiments: Path | None, live_port: int = 0) -> int:
    """Run the five stages (skipping finished ones); ``live_port`` serves the live view."""
    start = time.perf_counter()
    stage(1)
    if resume and (run_dir / VALIDATION).is_file():
        print('already validated (validation.json)')
    elif not validate_run(config, run_dir):
        print('validation failed: fix the environment before training (see above)')
        return 1
    stage(2)
    if (run_dir / FINAL_MODEL).is_file():
        print('already trained (final_model.zip)')
    else:
        summary = train(config, run_dir, resume=resume and bool(checkpoints(run_dir)),
                        resume_command='visnav-pipeline --resume', live_port=live_port)
        print(f"trained {summary['num_timesteps']} steps in {summary['wall_clock_s']:.0f} s "
              f"({summary['steps_per_s']} steps/s, env share {summary['env_share']:.1%})")
        if summary['interrupted']:
            return 130
    stage(3)
    sets = plan_sets(run_dir, list(DEFAULT_SETS), WORKSHOP_TRAIN, WORKSHOP_HELDOUT)
    results = evaluate(run_dir, sets, live_port=live_port)
    print(results_markdown(results['sets']))
    stage(4)
    try:
        diagnose_run(run_dir)
    except DiagnosisError as exc:
        print(f'no diagnosis: {exc}')
    stage(5)
    path = write_report(run_dir, experiments if experiments and experiments.is_file() else None)
    print(f'report: {path} (and {path.with_suffix(".html")})')
    print(f'pipeline finished in {time.perf_counter() - start:.0f} s; run directory {run_dir}')
    return 0


def main(argv: list[str] | None = None) -> None:
    """Run the ``visnav-pipeline`` command."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='YAML file with training settings '
                        '(default: the workshop settings, see config/train.yaml)')
    parser.add_argument('--resume', metavar='RUN_DIR', help='finish an interrupted pipeline')
    parser.add_argument('--experiments', type=Path, default=EXPERIMENTS_LOG,
                        help='Markdown log of task-design attempts to include in the report')
    train_config.add_arguments(parser)
    add_live_argument(parser)  # training, then evaluation, serve it in turn on the same port
    args = parser.parse_args(strip_ros_args(argv))
    overrides = {k: v for k, v in vars(args).items() if k in train_config.FIELDS}
    quiet_learner_threads()

    def body() -> int:
        config, run_dir = config_and_run_dir(args.config, overrides, args.resume)
        config = config.with_full_sim_params()
        if not args.resume:  # written now: an interrupted validation resumes too
            write_text(run_dir / CONFIG, config.to_yaml())
        print(f'run directory: {run_dir}', flush=True)
        return run_pipeline(config, run_dir, bool(args.resume), args.experiments,
                            live_port=args.live)

    run_command('visnav-pipeline', body)


if __name__ == '__main__':
    main()
