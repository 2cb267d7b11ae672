"""The trainer: a run directory, its env and model, training with checkpoints, the summary."""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

from nav_gym.env.navigation import NavigationEnv
from nav_gym.errors import CheckpointError, DiskFullError, TrainConfigError, TrainingError
from nav_gym.training import config as train_config
from nav_gym.training.checkpoints import (
    cut_at_resume,
    delete_replay_buffer,
    load_model,
    make_callback,
    replay_buffer_step,
    save_checkpoint,
    save_replay_buffer,
)
from nav_gym.training.config import TrainConfig
from nav_gym.training.files import atomic_write, link, write_text
from nav_gym.training.live_hooks import training_callback
from nav_gym.training.progress import progress_callback
from nav_gym.training.run_dir import (
    CHECKPOINTS,
    CONFIG,
    FINAL_MODEL,
    MONITOR,
    REPLAY_BUFFER,
    REPLAY_BUFFER_STEP,
    RESUME_COMMAND,
    SUMMARY,
    TENSORBOARD,
    checkpoint_path,
    checkpoints,
    load_config,
)
from nav_sim.errors import NavSimError, describe_exception, is_interrupt
from nav_sim.viz.options import add_live_argument


def new_run_dir(config: TrainConfig) -> Path:
    """Create the directory of a new run, or raise a one-line error."""
    name = config.run_name or datetime.now().strftime('dqn_%Y%m%d_%H%M%S')
    run_dir = Path(config.runs_dir) / name
    if (run_dir / CONFIG).exists():
        raise CheckpointError(f'{run_dir} already holds a run: resume it with --resume '
                              f'{run_dir}, or choose another --run-name')
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TrainConfigError(f'cannot create the run directory {run_dir} ({exc.strerror}); '
                               'choose another --runs-dir') from None
    return run_dir


def build_env(config: TrainConfig, run_dir: Path, resume: bool) -> Any:
    """Return the run's ``n_envs`` envs: ``ParallelEnvs`` of ``Monitor(NavigationEnv)``.

    With memory (``frame_stack`` > 1, ``previous_action``) they are wrapped in the agent's
    ``FrameStackEnv`` (:func:`nav_gym.training.memory.agent_envs`).

    Their episodes all go to the run's one monitor.csv (a resumed run appends to it).
    """
    # torch (SB3's VecEnv): after quiet_learner_threads()
    from nav_gym.training.memory import agent_envs
    from nav_gym.training.parallel import SETTLE_SECONDS, MonitorFile, ParallelEnvs
    monitor_file = run_dir / MONITOR
    writer = MonitorFile(str(monitor_file), resume and monitor_file.exists(),
                         ('is_success', 'event'))
    # a step that ends an episode waits on up to about five sim requests (stop, reset, ...)
    settle = max(SETTLE_SECONDS, 6 * config.sim_timeout)
    try:
        envs = ParallelEnvs([functools.partial(_monitored_env, writer, env_config)
                             for env_config in config.env_configs()], settle)
    except BaseException:
        writer.close()
        raise
    return agent_envs(envs, config.learner())  # the agent's memory, on its side of the envs


def _monitored_env(writer: Any, env_config: Any) -> Any:
    return writer.monitor(NavigationEnv(env_config))


def build_model(config: TrainConfig, run_dir: Path, env: Any, resume: bool) -> Any:
    """Return a new DQN, or the newest checkpoint's with its replay buffer when it has one."""
    if not resume:
        # torch: after quiet_learner_threads()
        from nav_gym.training.learner import learner_class, learner_kwargs, learner_policy
        learner = config.learner()
        # the learner's share of every env step is counted into the env's step budget
        return learner_class(env.first.timing, learner)(
            learner_policy(learner), env, tensorboard_log=str(run_dir / TENSORBOARD), verbose=0,
            **config.dqn_kwargs(), **learner_kwargs(learner, config.gamma))
    found = checkpoints(run_dir)
    if not found:
        raise CheckpointError(f'no checkpoint in {run_dir / CHECKPOINTS} to resume from')
    steps, path = found[-1]
    model = load_model(path, env, config.device, config.learner(), env.first.timing)
    model.tensorboard_log = str(run_dir / TENSORBOARD)
    buffer = run_dir / CHECKPOINTS / REPLAY_BUFFER
    buffer_step = replay_buffer_step(run_dir / CHECKPOINTS / REPLAY_BUFFER_STEP)
    if config.save_replay_buffer and buffer.exists() and buffer_step != steps:
        note = ('without a replay buffer (the saved one does not belong to this checkpoint)')
    elif config.save_replay_buffer and buffer.exists():
        try:
            model.load_replay_buffer(buffer)
        except Exception as exc:  # pickle/EOF/shape errors all mean the same to the user
            raise CheckpointError(f'replay buffer {buffer} is corrupt ({exc}); delete it to '
                                  'resume without it') from exc
        cut_at_resume(model.replay_buffer)  # the envs start new episodes
        note = f'with its replay buffer ({model.replay_buffer.size()} transitions)'
    else:
        note = 'without a replay buffer'
    print(f'resuming {run_dir} from {path.name} (step {steps}) {note}; '
          f'{max(config.total_timesteps - steps, 0)} steps remain', flush=True)
    return model


def train(config: TrainConfig, run_dir: Path, resume: bool = False, *,
          resume_command: str = RESUME_COMMAND, live_port: int = 0) -> dict[str, Any]:
    """Train (or continue) a run; returns the summary it writes.

    Ctrl-C returns a summary with ``interrupted`` set after saving a checkpoint; a sim that
    dies raises TrainingError after saving one; either message says how to resume (with
    ``resume_command RUN_DIR``).
    """
    config = config.with_full_sim_params()
    hint = f'continue with: {resume_command} {run_dir}'
    if resume and not checkpoints(run_dir):  # stopped before its first checkpoint
        print(f'{run_dir} has no checkpoint yet: training starts from step 0', flush=True)
        resume = False
    try:
        return _train(config, run_dir, resume, hint, live_port)
    except DiskFullError as exc:
        raise DiskFullError(f'{exc}, then {hint}') from None
    except KeyboardInterrupt:  # before learning started (or while closing the env)
        print(f'\ninterrupted; {hint}', flush=True)
        raise


def _train(config: TrainConfig, run_dir: Path, resume: bool, hint: str,
           live_port: int = 0) -> dict[str, Any]:
    write_text(run_dir / CONFIG, config.to_yaml())
    env = None
    start = time.perf_counter()
    try:
        env = build_env(config, run_dir, resume)
        if live_port:  # --live: this process serves the Foxglove live view (of env 0)
            print(f'live view: open {env.first.start_live(live_port)} in Foxglove', flush=True)
        model = build_model(config, run_dir, env, resume)
        steps_before = model.num_timesteps
        if not resume:
            save_checkpoint(model, run_dir, with_buffer=False)  # step-0 reference
        failure, error = None, None
        terminal = sys.stdout.isatty()  # a progress bar there; progress lines in a log
        callbacks = [make_callback(config, run_dir), training_callback(env.first)]
        if not terminal:
            callbacks.append(progress_callback(config.total_timesteps))
        try:
            model.learn(max(config.total_timesteps - steps_before, 0), callback=callbacks,
                        reset_num_timesteps=not resume,
                        tb_log_name='dqn', progress_bar=terminal)
            outcome = 'finished'
        except KeyboardInterrupt:
            outcome = 'interrupted'
        except NavSimError as exc:  # the sim died or stopped answering
            outcome, failure = 'sim failed', _sim_failure(env, exc)
        except Exception as exc:  # noqa: BLE001 - a library's error: keep what was learned
            if is_interrupt(exc):  # a Ctrl-C that a C extension reported as another error
                outcome = 'interrupted'
            else:
                outcome, failure, error = 'failed', f'unexpected {describe_exception(exc)}', exc
        summary = _summary(config, run_dir, resume, outcome, model, steps_before,
                           time.perf_counter() - start, env)
        saved: list[str] = []
        try:
            path = _save(model, config, run_dir, summary, saved)
        except KeyboardInterrupt:
            summary['interrupted'] = True
            found = checkpoints(run_dir)
            newest = f' (step {found[-1][0]})' if found else ''
            state = ('the run is complete (final_model.zip, summary.json)' if saved else
                     f'the run resumes from its newest complete checkpoint{newest}')
            print(f'\ninterrupted while saving at step {model.num_timesteps}: {state}; {hint}',
                  flush=True)
            return summary
    finally:
        if env is not None:
            env.close()
    if failure is not None:
        raise TrainingError(f'{failure}; saved {path} (step {model.num_timesteps}); {hint}'
                            ) from error
    if outcome == 'interrupted':
        print(f'\ninterrupted at step {model.num_timesteps}: checkpoint {path}; {hint}',
              flush=True)
    return summary


def config_and_run_dir(config_file: str | None, overrides: dict[str, Any],
                       resume: str | None) -> tuple[TrainConfig, Path]:
    """Return the config and the directory of a new run, or of the run ``resume`` names.

    A resumed run's config.yaml is the base (a directory without one is refused with
    RunDirError); the config file and the command line still override it.  A new run's
    directory is created (:func:`new_run_dir`).
    """
    if resume:
        run_dir = Path(resume)
        saved = load_config(run_dir)
        config = train_config.build(config_file, overrides, dataclasses.asdict(saved))
        if config.n_envs != saved.n_envs:  # its replay buffer and schedule are per env
            raise TrainConfigError(f'{run_dir} was trained with n_envs {saved.n_envs} and '
                                   f'resumes with it, not {config.n_envs}')
        return config, run_dir
    config = train_config.build(config_file, overrides)
    return config, new_run_dir(config)


def _sim_failure(env: Any, exc: NavSimError) -> str:
    """Say what happened to the sim: the embedded one's exit code and log tail, if it died."""
    died = env.sim_failure()
    if died is not None:
        return f'the embedded sim died ({died})'
    return f'the sim stopped answering ({exc})'


def _save(model: Any, config: TrainConfig, run_dir: Path, summary: dict[str, Any],
          saved: list[str]) -> Path:
    """Save the end of a session and return the checkpoint written.

    A finished run writes its final model and summary first (then appends 'final' to
    ``saved``), deletes or keeps the replay buffer, and makes its last checkpoint a hard link
    of the final model (the same file: 27 MB less on disk).
    """
    if summary['interrupted']:
        path = save_checkpoint(model, run_dir, config.save_replay_buffer)
        _write_summary(run_dir, summary)
        return path
    final = run_dir / FINAL_MODEL
    atomic_write(final, model.save)
    _write_summary(run_dir, summary)
    saved.append('final')
    keep = config.save_replay_buffer and config.keep_replay_buffer
    if not keep:
        delete_replay_buffer(run_dir)  # a finished run does not need it (see README)
    path = checkpoint_path(run_dir, model.num_timesteps)
    if not link(final, path):
        save_checkpoint(model, run_dir, with_buffer=False)
    if keep:
        save_replay_buffer(model, path.parent)
    return path


def _summary(config: TrainConfig, run_dir: Path, resume: bool, outcome: str, model: Any,
             steps_before: int, wall: float, env: Any) -> dict[str, Any]:
    steps = model.num_timesteps - steps_before
    return {
        'run_dir': str(run_dir), 'interrupted': outcome != 'finished', 'outcome': outcome,
        'resumed': resume, 'total_timesteps': config.total_timesteps,
        'num_timesteps': model.num_timesteps, 'steps_this_session': steps,
        'wall_clock_s': round(wall, 2),
        'steps_per_s': round(steps / wall, 2) if wall > 0 else None,
        'n_envs': env.num_envs,
        'env_time_s': round(env.env_seconds, 2),
        'env_share': round(env.env_seconds / wall, 4) if wall > 0 else None,
        'omp_wait_policy': os.environ.get('OMP_WAIT_POLICY', 'default'),
        'episodes': env.episode_count(),
        # mean ms per step of env 0: env phases, the learner's share (per vector step), the
        # sim's period (/diagnostics)
        'time_budget': env.first.time_budget(),
        'config': dataclasses.asdict(config),
    }


def _write_summary(run_dir: Path, summary: dict[str, Any]) -> None:
    path = run_dir / SUMMARY
    sessions = []
    if path.exists():
        try:
            sessions = json.loads(path.read_text()).get('sessions', [])
        except (OSError, ValueError):
            sessions = []
    sessions.append({k: v for k, v in summary.items() if k != 'config'})
    summary = {**summary, 'sessions': sessions,
               'wall_clock_total_s': round(sum(s['wall_clock_s'] for s in sessions), 2)}
    write_text(path, json.dumps(summary, indent=2))


def command_parser(description: str) -> argparse.ArgumentParser:
    """Return nav-gym-train's argument parser: --config, --resume, every setting, --live."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument('--config', help='YAML file with settings (see config/train.yaml)')
    parser.add_argument('--resume', metavar='RUN_DIR', help='continue a run from its newest '
                        'checkpoint (its config.yaml is the base; flags still override)')
    train_config.add_arguments(parser)
    add_live_argument(parser)
    return parser


def run_training(args: argparse.Namespace) -> int:
    """Train as nav-gym-train does with parsed ``args``; return its exit code (130: stopped)."""
    overrides = {k: v for k, v in vars(args).items() if k in train_config.FIELDS}
    config, run_dir = config_and_run_dir(args.config, overrides, args.resume)
    print(f'run directory: {run_dir}', flush=True)
    summary = train(config, run_dir, resume=bool(args.resume), live_port=args.live)
    print(f"trained {summary['steps_this_session']} steps in {summary['wall_clock_s']} s "
          f"({summary['steps_per_s']} steps/s, env share {summary['env_share']:.1%}); "
          f"episodes: {summary['episodes']}")
    return 130 if summary['interrupted'] else 0
