"""Checkpoints and the replay buffer of a run: save, load, delete, and the saving callback."""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from nav_gym.errors import CheckpointError
from nav_gym.training.config import TrainConfig
from nav_gym.training.files import atomic_write, write_text
from nav_gym.training.run_dir import (
    CHECKPOINTS,
    REPLAY_BUFFER,
    REPLAY_BUFFER_STEP,
    checkpoint_path,
    checkpoints,
    on_schedule,
)
from nav_gym.training.spec import LearnerSpec


def buffer_nbytes(buffer: Any) -> int:
    """Return the bytes a replay buffer's arrays hold (what saving it needs, roughly)."""
    return sum(int(getattr(value, 'nbytes', 0)) for value in vars(buffer).values())


def cut_at_resume(buffer: Any) -> None:
    """End each env's last stored episode at the newest transition, as a time-out.

    A resumed run starts new episodes (its envs reset), but the saved buffer's newest transition
    of an env whose episode was still running says "not done".  Uncut, SB3's n-step returns
    would add the new episode's rewards to the old episode's last transition, and the agent's
    memory (frame stacks, the previous action) would join the two episodes.  An episode cut
    by the interruption is a time-out: it bootstraps from its stored next observation, as
    SB3 does at a time limit (``handle_timeout_termination``).  A buffer that does not handle
    time-outs is left as it is.
    """
    if buffer.size() == 0 or not getattr(buffer, 'handle_timeout_termination', False):
        return
    last = (buffer.pos - 1) % buffer.buffer_size
    running = buffer.dones[last] == 0
    buffer.timeouts[last] = np.where(running, 1, buffer.timeouts[last])
    buffer.dones[last] = np.where(running, 1, buffer.dones[last])


def save_checkpoint(model: Any, run_dir: Path, with_buffer: bool) -> Path:
    """Save ``checkpoints/dqn_<steps>_steps.zip`` (and the replay buffer that belongs to it)."""
    folder = run_dir / CHECKPOINTS
    folder.mkdir(parents=True, exist_ok=True)
    path = checkpoint_path(run_dir, model.num_timesteps)
    found = checkpoints(run_dir)
    atomic_write(path, model.save, found[-1][1].stat().st_size if found else None)
    if with_buffer:
        save_replay_buffer(model, folder)
    return path


def save_replay_buffer(model: Any, folder: Path) -> None:
    """Replace the replay buffer; its step marker exists only while the two belong together."""
    marker = folder / REPLAY_BUFFER_STEP
    marker.unlink(missing_ok=True)
    atomic_write(folder / REPLAY_BUFFER, model.save_replay_buffer,
                 buffer_nbytes(model.replay_buffer))
    write_text(marker, str(model.num_timesteps))


def delete_replay_buffer(run_dir: Path) -> None:
    """Delete the replay buffer and its step marker (marker first)."""
    folder = run_dir / CHECKPOINTS
    (folder / REPLAY_BUFFER_STEP).unlink(missing_ok=True)
    (folder / REPLAY_BUFFER).unlink(missing_ok=True)


def load_model(path: Path, env: Any, device: str, learner: LearnerSpec | None = None,
               timing: Any = None) -> Any:
    """Load a checkpoint to train ``learner`` on ``env``, its work counted into ``timing``.

    ``timing`` is env 0's step budget, as :func:`build_model` times a new learner.

    Raises CheckpointError when the file is corrupt or incompatible.
    """
    from nav_gym.training.learner import load_checkpoint  # torch: after quiet_learner_threads()
    try:
        return load_checkpoint(path, learner or LearnerSpec(), timing, env=env, device=device)
    except (zipfile.BadZipFile, EOFError, KeyError, ValueError, RuntimeError, OSError,
            AssertionError) as exc:
        raise CheckpointError(
            f'checkpoint {path} is corrupt or incompatible ({type(exc).__name__}: {exc}); '
            'delete it to resume from the previous one, or start a new run') from exc


def make_callback(config: TrainConfig, run_dir: Path) -> Any:
    """Return the SB3 callback that saves a checkpoint every ``checkpoint_freq`` steps."""
    from stable_baselines3.common.callbacks import BaseCallback

    class AtomicCheckpoint(BaseCallback):
        """CheckpointCallback with atomic writes and the latest replay buffer."""

        def _on_step(self) -> bool:
            if on_schedule(self.num_timesteps, self.training_env.num_envs,
                           config.checkpoint_freq):
                path = save_checkpoint(self.model, run_dir, config.save_replay_buffer)
                print(f'checkpoint: {path}', flush=True)
            return True

    return AtomicCheckpoint()


def replay_buffer_step(path: Path) -> int | None:
    """Return the step a replay buffer's marker file names (None: no marker, or unreadable)."""
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None
