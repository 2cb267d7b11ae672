"""The frame-stack learner's two halves on SB3: the agent's history and its replay.

The env's contract does not change (one ``(3, 84, 84)`` frame per step).  The agent keeps its
last ``k`` frames (:class:`nav_gym.policy.history.FrameHistory`, the one stack rule):

- :class:`FrameStackEnv`, a VecEnv wrapper on the agent's side, gives the learner each env's
  stacked observation, begun afresh at every episode start (an ended episode's
  ``terminal_observation`` is its stack too), with the previous action's planes where the
  learner takes it (``previous_action``);
- :class:`FrameStackReplayBuffer`, SB3's n-step buffer storing single frames: what SB3 adds is
  cut to its newest frame, and sampling rebuilds the stacks with
  :func:`nav_gym.policy.history.history_positions` (and the action planes from the actions
  it keeps anyway), so that the buffer's memory does not grow k-fold.  SB3's own sampling
  (n-step returns, time-outs) runs unchanged on top.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from nav_gym.env.observation import OBS_SHAPE
from nav_gym.policy.history import NO_ACTION, FrameHistory, action_planes, history_positions

if TYPE_CHECKING:
    from nav_gym.training.spec import LearnerSpec


def stacked_space(space: spaces.Box, k: int, n_actions: int = 0) -> spaces.Box:
    """Return the space of ``k`` frames of ``space`` stacked along the channels.

    ``n_actions`` > 0 adds that many action planes (0 or 255) after the frames.
    """
    planes = np.zeros((n_actions, *space.shape[1:]), space.dtype)
    return spaces.Box(np.concatenate([space.low] * k + [planes], axis=0),
                      np.concatenate([space.high] * k + [planes + 255], axis=0),
                      dtype=space.dtype)


def frame_space(space: spaces.Box, k: int, n_actions: int = 0) -> spaces.Box:
    """Return the space of one frame of a ``k``-frame stack's ``space``.

    Raises ValueError when ``space`` is no such stack (:func:`refuse_unstacked`).
    """
    channels = (space.shape[0] - n_actions) // k
    if channels < 1 or channels * k + n_actions != space.shape[0]:
        raise ValueError(f'observations of shape {space.shape} are not {k}-frame stacks with '
                         f'{n_actions} action planes')
    return spaces.Box(space.low[:channels], space.high[:channels], dtype=space.dtype)


def refuse_unstacked(space: spaces.Space, k: int, n_actions: int = 0) -> None:
    """Raise ValueError unless ``space`` is the camera's frames stacked ``k`` deep (+ actions).

    A learner with memory acts on the agent's stacks (:class:`FrameStackEnv`), not on an env's
    own frames; given those, its replay buffer would split them into frames of the wrong size.
    """
    frame = spaces.Box(0, 255, OBS_SHAPE, np.uint8)
    if space.shape != stacked_space(frame, k, n_actions).shape:
        raise ValueError(f'observations of shape {space.shape} are not {k}-frame stacks with '
                         f'{n_actions} action planes: a learner with memory acts on the '
                         'FrameStackEnv of its envs (nav_gym.training.memory)')


class FrameStackEnv(VecEnvWrapper):
    """Each env's last ``k`` frames as its observation (the agent's side, not the env's).

    With ``previous_action``, the planes of the action that led to the latest frame follow.
    """

    def __init__(self, venv: VecEnv, k: int, previous_action: bool = False) -> None:
        """Wrap ``venv``; every env gets its own :class:`FrameHistory`."""
        n_actions = int(venv.action_space.n) if previous_action else 0
        super().__init__(venv, observation_space=stacked_space(venv.observation_space, k,
                                                               n_actions))
        self.histories = [FrameHistory(k, n_actions) for _ in range(venv.num_envs)]
        self._actions = np.full(venv.num_envs, NO_ACTION)

    def step_async(self, actions: np.ndarray) -> None:
        """Send ``actions``, kept as the previous actions of the frames they lead to."""
        self._actions = np.asarray(actions).reshape(-1)
        self.venv.step_async(actions)

    def reset(self) -> np.ndarray:
        """Reset the envs and begin every history."""
        frames = self.venv.reset()
        return np.stack([h.begin(f) for h, f in zip(self.histories, frames, strict=True)])

    def step_wait(self) -> Any:
        """Push each env's frame; an ended episode's history ends with its terminal frame."""
        frames, rewards, dones, infos = self.venv.step_wait()
        out = []
        for history, frame, done, info, action in zip(self.histories, frames, dones, infos,
                                                      self._actions, strict=True):
            if done:
                info['terminal_observation'] = history.push(info['terminal_observation'],
                                                            action)
                out.append(history.begin(frame))  # the next episode's first frame
            else:
                out.append(history.push(frame, action))
        return np.stack(out), rewards, dones, infos


def agent_envs(venv: VecEnv, learner: LearnerSpec) -> VecEnv:
    """Return ``venv`` as ``learner`` acts on it: in its :class:`FrameStackEnv` with memory.

    The one place where training, the benchmarks and the tests give a learner its envs.
    """
    if not learner.memory:
        return venv
    return FrameStackEnv(venv, learner.frame_stack, learner.previous_action)


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
        channels, k = self.frames.shape[2], self.buffer.frame_stack
        self.frames[position] = np.asarray(stacked)[:, (k - 1) * channels:k * channels]

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Return the stacks at ``(positions, envs)``: ``(len(positions), k C [+ A], H, W)``."""
        positions, envs = (np.asarray(i) for i in index)
        buffer = self.buffer
        rows = buffer.stack_positions(positions, envs)
        frames = buffer.observations.frames[rows, envs[:, None]]  # (B, k, C, H, W)
        if self.next:  # the frames after each transition: drop the oldest, add its next frame
            frames = np.concatenate(
                [frames[:, 1:], self.frames[positions, envs][:, None]], axis=1)
        stacks = frames.reshape(len(positions), -1, *frames.shape[3:])
        if not buffer.n_actions:
            return stacks
        # the action that led to the newest frame: the stored one for the frame after a
        # transition, else the one before it in the same episode (none at its first frame)
        actions = (buffer.actions[positions, envs, 0] if self.next
                   else buffer.previous_actions(positions, envs))
        return np.concatenate([stacks, action_planes(actions, buffer.n_actions,
                                                     frames.shape[3:])], axis=1)


class FrameStackReplayBuffer(NStepReplayBuffer):
    """SB3's n-step replay buffer of single frames that samples ``frame_stack``-frame stacks.

    With ``previous_action``, each stack ends with the planes of the action before its newest
    frame, rebuilt from the actions the buffer keeps.
    """

    n_actions = 0  # a buffer pickled before the previous action existed has none

    def __init__(self, buffer_size: int, observation_space: spaces.Box,
                 action_space: spaces.Discrete, *args: Any, frame_stack: int = 1,
                 previous_action: bool = False, **kwargs: Any) -> None:
        """Store frames of ``observation_space`` (a stack's space) one by one."""
        self.frame_stack = frame_stack
        self.n_actions = int(action_space.n) if previous_action else 0
        super().__init__(buffer_size, frame_space(observation_space, frame_stack,
                                                  self.n_actions), action_space, *args,
                         **kwargs)
        self.observation_space = observation_space
        self.observations = FrameStore(self.observations, self, nxt=False)
        self.next_observations = FrameStore(self.next_observations, self, nxt=True)

    def stack_positions(self, positions: np.ndarray, envs: np.ndarray) -> np.ndarray:
        """Return the positions of each ``(position, env)``'s stack, ``(B, k)``, oldest first.

        A frame begins an episode where the transition stored before it ended one, and at the
        oldest frame kept (nothing before it is the same episode any more).
        """
        return history_positions(positions, self.frame_stack, self.buffer_size,
                                 lambda q: self.begins(q, envs))

    def begins(self, positions: np.ndarray, envs: np.ndarray) -> np.ndarray:
        """Tell whether the frame at each ``(position, env)`` begins an episode, as replayed.

        It does where the transition stored before it ended one, and at the oldest frame kept.
        """
        oldest = self.pos if self.full else 0
        return (positions == oldest) | self.dones[(positions - 1) % self.buffer_size,
                                                  envs].astype(bool)

    def previous_actions(self, positions: np.ndarray, envs: np.ndarray) -> np.ndarray:
        """Return the action before each ``(position, env)``'s frame (-1 where it begins one)."""
        before = self.actions[(positions - 1) % self.buffer_size, envs, 0].astype(np.int64)
        return np.where(self.begins(positions, envs), NO_ACTION, before)
