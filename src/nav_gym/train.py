"""Training node: SB3 ``DQN('CnnPolicy')`` on ``Monitor(NavigationEnv)`` through the ROS graph.

    ros2 run nav_gym train [--config config/train.yaml] [--total-timesteps N] [...]
    nav-gym-train --resume runs/dqn_20261122_101500

A run directory holds: ``config.yaml`` (effective settings), ``monitor.csv``, ``tb/``
(TensorBoard), ``checkpoints/dqn_<steps>_steps.zip`` (every ``checkpoint_freq`` steps, all kept,
written atomically) with the latest replay buffer, ``final_model.zip`` and ``summary.json``
(wall-clock time, steps/s, the environment's share of the time).  Ctrl-C saves a checkpoint.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
import zipfile
from dataclasses import asdict
from datetime import datetime
from pathlib import Path
from typing import Any

from nav_gym import train_config
from nav_gym.checkpoints import checkpoints
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.env import NavigationEnv
from nav_gym.errors import CheckpointError
from nav_gym.timing import EnvTimer, quiet_learner_threads
from nav_gym.train_config import TrainConfig

REPLAY_BUFFER = 'replay_buffer.pkl'
REPLAY_BUFFER_STEP = 'replay_buffer.step'


def atomic_write(path: Path, write: Any) -> None:
    """Write through ``write(fileobj)`` to a temporary file, fsync, then rename over ``path``."""
    tmp = path.with_name(f'.{path.name}.tmp')
    with open(tmp, 'wb') as handle:
        write(handle)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def save_checkpoint(model: Any, run_dir: Path, with_buffer: bool) -> Path:
    folder = run_dir / 'checkpoints'
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f'dqn_{model.num_timesteps}_steps.zip'
    atomic_write(path, model.save)
    if with_buffer:
        atomic_write(folder / REPLAY_BUFFER, model.save_replay_buffer)
        # which checkpoint the buffer belongs to: resume loads it only with that one
        atomic_write(folder / REPLAY_BUFFER_STEP,
                     lambda h: h.write(str(model.num_timesteps).encode()))
    return path


def load_model(path: Path, env: Any, device: str) -> Any:
    """Load a DQN checkpoint or raise CheckpointError saying what to do."""
    from stable_baselines3 import DQN
    try:
        return DQN.load(path, env=env, device=device)
    except (zipfile.BadZipFile, EOFError, KeyError, ValueError, RuntimeError, OSError,
            AssertionError) as exc:
        raise CheckpointError(
            f'checkpoint {path} is corrupt or incompatible ({type(exc).__name__}: {exc}); '
            'delete it to resume from the previous one, or start a new run') from exc


def make_callback(config: TrainConfig, run_dir: Path) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class AtomicCheckpoint(BaseCallback):
        """CheckpointCallback with atomic writes and the latest replay buffer."""

        def _on_step(self) -> bool:
            if self.num_timesteps % config.checkpoint_freq == 0:
                path = save_checkpoint(self.model, run_dir, config.save_replay_buffer)
                print(f'checkpoint: {path}', flush=True)
            return True

    return AtomicCheckpoint()


def new_run_dir(config: TrainConfig) -> Path:
    name = config.run_name or datetime.now().strftime('dqn_%Y%m%d_%H%M%S')
    run_dir = Path(config.runs_dir) / name
    if (run_dir / 'config.yaml').exists():
        raise CheckpointError(f'{run_dir} already holds a run: resume it with --resume '
                              f'{run_dir}, or choose another --run-name')
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def build_env(config: TrainConfig, run_dir: Path, resume: bool) -> tuple[Any, EnvTimer]:
    from stable_baselines3.common.monitor import Monitor
    monitor_file = run_dir / 'monitor.csv'
    timer = EnvTimer(NavigationEnv(config.env_config()))
    # a resumed run appends to its Monitor CSV (SB3 writes the header only for a new file)
    env = Monitor(timer, str(monitor_file), info_keywords=('is_success', 'event'),
                  override_existing=not (resume and monitor_file.exists()))
    return env, timer


def build_model(config: TrainConfig, run_dir: Path, env: Any, resume: bool) -> Any:
    from stable_baselines3 import DQN
    if not resume:
        return DQN('CnnPolicy', env, tensorboard_log=str(run_dir / 'tb'), verbose=0,
                   **config.dqn_kwargs())
    found = checkpoints(run_dir)
    if not found:
        raise CheckpointError(f'no checkpoint in {run_dir / "checkpoints"} to resume from')
    steps, path = found[-1]
    model = load_model(path, env, config.device)
    model.tensorboard_log = str(run_dir / 'tb')
    buffer = run_dir / 'checkpoints' / REPLAY_BUFFER
    buffer_step = _buffer_step(run_dir / 'checkpoints' / REPLAY_BUFFER_STEP)
    if config.save_replay_buffer and buffer.exists() and buffer_step != steps:
        note = (f'without a replay buffer (the saved one belongs to step {buffer_step}, not to '
                f'this checkpoint)')
    elif config.save_replay_buffer and buffer.exists():
        try:
            model.load_replay_buffer(buffer)
        except Exception as exc:  # pickle/EOF/shape errors all mean the same to the user
            raise CheckpointError(f'replay buffer {buffer} is corrupt ({exc}); delete it to '
                                  'resume without it') from exc
        note = f'with its replay buffer ({model.replay_buffer.size()} transitions)'
    else:
        note = 'without a replay buffer'
    print(f'resuming {run_dir} from {path.name} (step {steps}) {note}; '
          f'{max(config.total_timesteps - steps, 0)} steps remain', flush=True)
    return model


def _buffer_step(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


def train(config: TrainConfig, run_dir: Path, resume: bool = False) -> dict[str, Any]:
    """Train (or continue) a run; returns the summary it writes."""
    config = config.with_full_sim_params()
    (run_dir / 'config.yaml').write_text(config.to_yaml())
    env = None
    interrupted = False
    start = time.perf_counter()
    try:
        env, timer = build_env(config, run_dir, resume)
        model = build_model(config, run_dir, env, resume)
        steps_before = model.num_timesteps
        remaining = max(config.total_timesteps - steps_before, 0)
        if not resume:
            save_checkpoint(model, run_dir, with_buffer=False)  # step-0 reference
        try:
            model.learn(remaining, callback=make_callback(config, run_dir),
                        reset_num_timesteps=not resume, tb_log_name='dqn',
                        progress_bar=sys.stdout.isatty())
        except KeyboardInterrupt:
            interrupted = True
            path = save_checkpoint(model, run_dir, config.save_replay_buffer)
            print(f'\ninterrupted at step {model.num_timesteps}: checkpoint {path}; continue '
                  f'with: nav-gym-train --resume {run_dir}', flush=True)
        else:
            save_checkpoint(model, run_dir, config.save_replay_buffer)
            atomic_write(run_dir / 'final_model.zip', model.save)
        wall = time.perf_counter() - start
        steps = model.num_timesteps - steps_before
    finally:
        if env is not None:
            env.close()
    summary = {
        'run_dir': str(run_dir), 'interrupted': interrupted, 'resumed': resume,
        'total_timesteps': config.total_timesteps, 'num_timesteps': model.num_timesteps,
        'steps_this_session': steps, 'wall_clock_s': round(wall, 2),
        'steps_per_s': round(steps / wall, 2) if wall > 0 else None,
        'env_time_s': round(timer.env_seconds, 2),
        'env_share': round(timer.env_seconds / wall, 4) if wall > 0 else None,
        'omp_wait_policy': os.environ.get('OMP_WAIT_POLICY', 'default'),
        'episodes': len(env.get_episode_rewards()),
        'config': asdict(config),
    }
    _write_summary(run_dir, summary)
    return summary


def _write_summary(run_dir: Path, summary: dict[str, Any]) -> None:
    path = run_dir / 'summary.json'
    sessions = []
    if path.exists():
        try:
            sessions = json.loads(path.read_text()).get('sessions', [])
        except (OSError, ValueError):
            sessions = []
    sessions.append({k: v for k, v in summary.items() if k != 'config'})
    summary = {**summary, 'sessions': sessions,
               'wall_clock_total_s': round(sum(s['wall_clock_s'] for s in sessions), 2)}
    atomic_write(path, lambda h: h.write(json.dumps(summary, indent=2).encode()))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='YAML file with settings (see config/train.yaml)')
    parser.add_argument('--resume', metavar='RUN_DIR', help='continue a run from its newest '
                        'checkpoint (its config.yaml is the base; flags still override)')
    train_config.add_arguments(parser)
    args = parser.parse_args(strip_ros_args(argv))
    overrides = {k: v for k, v in vars(args).items() if k in train_config.FIELDS}
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    quiet_learner_threads()

    def body() -> int:
        if args.resume:
            run_dir = Path(args.resume)
            if not (run_dir / 'config.yaml').is_file():
                raise CheckpointError(f'{run_dir} is not a run directory (no config.yaml)')
            base = train_config.load_yaml(run_dir / 'config.yaml')
            config = train_config.build(args.config, overrides, base)
        else:
            config = train_config.build(args.config, overrides)
            run_dir = new_run_dir(config)
        print(f'run directory: {run_dir}', flush=True)
        summary = train(config, run_dir, resume=bool(args.resume))
        print(f"trained {summary['steps_this_session']} steps in {summary['wall_clock_s']} s "
              f"({summary['steps_per_s']} steps/s, env share {summary['env_share']:.1%}); "
              f"episodes: {summary['episodes']}")
        return 130 if summary['interrupted'] else 0

    run_command('nav-gym-train', body)


def _raise_keyboard_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


if __name__ == '__main__':
    main()
