"""The frame-stack learner's two halves on SB3: the agent's history and its replay.

The env's contract does not change (one ``(3, 84, 84)`` frame per step).  The agent keeps its
last ``k`` frames (:class:`nav_gym.policy.history.FrameHistory`, the one stack rule):

- :class:`FrameStackEnv`, a VecEnv wrapper on the agent's side, gives the learner each env's
  stacked observation, begun afresh at every episode start (an ended episode's
  ``terminal_observation`` is its stack too);
- :class:`FrameStackReplayBuffer`, SB3's n-step buffer storing single frames: what SB3 adds is
  cut to its newest frame, and sampling rebuilds the stacks with
  :func:`nav_gym.policy.history.history_positions`, so that the buffer's memory does not grow
  k-fold.  SB3's own sampling (n-step returns, time-outs) runs unchanged on top.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from nav_gym.policy.history import FrameHistory, history_positions


def stacked_space(space: spaces.Box, k: int) -> spaces.Box:
    """Return the space of ``k`` frames of ``space`` stacked along the channels."""
    return spaces.Box(np.concatenate([space.low] * k, axis=0),
                      np.concatenate([space.high] * k, axis=0), dtype=space.dtype)


def frame_space(space: spaces.Box, k: int) -> spaces.Box:
    """Return the space of one frame of a ``k``-frame stack's ``space``."""
    channels = space.shape[0] // k
    return spaces.Box(space.low[:channels], space.high[:channels], dtype=space.dtype)


class FrameStackEnv(VecEnvWrapper):
    """Each env's last ``k`` frames as its observation (the agent's side, not the env's)."""

    def __init__(self, venv: VecEnv, k: int) -> None:
        """Wrap ``venv``; every env gets its own :class:`FrameHistory`."""
        super().__init__(venv, observation_space=stacked_space(venv.observation_space, k))
        self.histories = [FrameHistory(k) for _ in range(venv.num_envs)]

    def reset(self) -> np.ndarray:
        """Reset the envs and begin every history."""
        frames = self.venv.reset()
        return np.stack([h.begin(f) for h, f in zip(self.histories, frames, strict=True)])

    def step_wait(self) -> Any:
        """Push each env's frame; an ended episode's history ends with its terminal frame."""
        frames, rewards, dones, infos = self.venv.step_wait()
        out = []
        for history, frame, done, info in zip(self.histories, frames, dones, infos,
                                              strict=True):
            if done:
                info['terminal_observation'] = history.push(info['terminal_observation'])
                out.append(history.begin(frame))  # the next episode's first frame
            else:
                out.append(history.push(frame))
        return np.stack(out), rewards, dones, infos


class FrameStore:
    """A replay buffer's frames, read as stacks: what SB3 writes and indexes as observations.

    ``store[pos] = stacked`` keeps the newest frame of each env's stack; ``store[positions,
    envs]`` returns the stacks (``next``: the stack after each position's transition, its
    newest frame the stored next frame).
    """

    def __init__(self, frames: np.ndarray, buffer: FrameStackReplayBuffer, nxt: bool) -> None:
        """Hold ``frames`` ``(size, n_envs, C, H, W)`` of ``buffer``."""
        self.frames, self.buffer, self.next = frames, buffer, nxt

    @property
    def nbytes(self) -> int:
        """Return the bytes the frames take."""
        return int(self.frames.nbytes)

    def __setitem__(self, position: int, stacked: np.ndarray) -> None:
        """Keep the newest frame of each env's stacked observation at ``position``."""
        self.frames[position] = np.asarray(stacked)[:, -self.frames.shape[2]:]

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Return the stacks at ``(positions, envs)``: ``(len(positions), k C, H, W)``."""
        positions, envs = (np.asarray(i) for i in index)
        buffer = self.buffer
        rows = buffer.stack_positions(positions, envs)
        frames = buffer.observations.frames[rows, envs[:, None]]  # (B, k, C, H, W)
        if self.next:  # the frames after each transition: drop the oldest, add its next frame
            frames = np.concatenate(
                [frames[:, 1:], self.frames[positions, envs][:, None]], axis=1)
        return frames.reshape(len(positions), -1, *frames.shape[3:])


class FrameStackReplayBuffer(NStepReplayBuffer):
    """SB3's n-step replay buffer of single frames that samples ``frame_stack``-frame stacks."""

    def __init__(self, buffer_size: int, observation_space: spaces.Box, *args: Any,
                 frame_stack: int = 1, **kwargs: Any) -> None:
        """Store frames of ``observation_space`` (a stack's space) one by one."""
        self.frame_stack = frame_stack
        super().__init__(buffer_size, frame_space(observation_space, frame_stack), *args,
                         **kwargs)
        self.observation_space = observation_space
        self.observations = FrameStore(self.observations, self, nxt=False)
        self.next_observations = FrameStore(self.next_observations, self, nxt=True)

    def stack_positions(self, positions: np.ndarray, envs: np.ndarray) -> np.ndarray:
        """Return the positions of each ``(position, env)``'s stack, ``(B, k)``, oldest first.

        A frame begins an episode where the transition stored before it ended one, and at the
        oldest frame kept (nothing before it is the same episode any more).
        """
        oldest = self.pos if self.full else 0

        def begins(q: np.ndarray) -> np.ndarray:
            return (q == oldest) | self.dones[(q - 1) % self.buffer_size, envs].astype(bool)

        return history_positions(positions, self.frame_stack, self.buffer_size, begins)
