"""The agent's memory of its last frames: one definition for acting and for replay (no torch).

A frame stack of ``k`` frames is the latest camera frame and the ``k - 1`` before it in the same
episode, oldest first, concatenated along the channels: ``(3 k, 84, 84)`` uint8 for the env's
``(3, 84, 84)`` frames.  At an episode's start there are no earlier frames: its first frame
stands in for them (as Gymnasium's ``FrameStackObservation`` pads with the reset observation).

With the previous action (Mirowski et al. 2017), ``n_actions`` planes follow the frames: the
plane of the action taken before the latest frame is 255, the others 0, and all are 0 at an
episode's first frame (no action was taken in it yet).  An image network reads them as one-hot
inputs (``/ 255``), and a random shift leaves them as they are.

Acting keeps the frames in :class:`FrameHistory` through :class:`EpisodeMemory` (begun at each
episode start: the acting protocol's ``begin_episode``), the same for the checkpoint's actor
and the exported one; the replay buffer stores single frames and rebuilds the same
stacks at sample time with :func:`history_positions` and :func:`action_planes`, so that its
memory does not grow k-fold.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np


def stack(frames: list[np.ndarray]) -> np.ndarray:
    """Concatenate ``(C, H, W)`` frames, oldest first, into one ``(k C, H, W)`` observation."""
    return np.concatenate(frames, axis=0)


NO_ACTION = -1  # the previous action at an episode's first frame: none


def action_planes(actions: np.ndarray, n_actions: int, shape: tuple[int, int]) -> np.ndarray:
    """Return one-hot uint8 planes ``(len(actions), n_actions, H, W)`` of previous actions.

    The plane of each action is 255, the others 0; :data:`NO_ACTION` (-1) gives all zeros.
    """
    actions = np.asarray(actions, dtype=np.int64).reshape(-1)
    hot = (actions[:, None] == np.arange(n_actions)[None, :]).astype(np.uint8) * 255
    return np.broadcast_to(hot[:, :, None, None], (len(actions), n_actions, *shape)).copy()


class FrameHistory:
    """The last ``k`` frames of the current episode (and the action before the latest one)."""

    def __init__(self, k: int, n_actions: int = 0) -> None:
        """Keep ``k`` >= 1 frames (1: the frame alone); ``n_actions`` > 0 adds action planes."""
        if k < 1:
            raise ValueError(f'a frame history holds at least 1 frame, got {k}')
        self.k, self.n_actions = k, n_actions
        self._frames: deque[np.ndarray] = deque(maxlen=k)
        self._action = NO_ACTION

    def begin(self, frame: np.ndarray) -> np.ndarray:
        """Start an episode with its first frame; return the first stacked observation."""
        self._frames.clear()
        self._frames.extend([frame] * self.k)
        self._action = NO_ACTION
        return self.observation()

    def push(self, frame: np.ndarray, action: int = NO_ACTION) -> np.ndarray:
        """Add the latest frame of the episode, which ``action`` led to; return the stack."""
        if not self._frames:
            raise RuntimeError('push before begin: an episode starts with begin(first frame)')
        self._frames.append(frame)
        self._action = int(action)
        return self.observation()

    def observation(self) -> np.ndarray:
        """Return the stack of the last ``k`` frames, oldest first (then the action planes)."""
        frames = list(self._frames)
        if self.n_actions:
            frames.append(action_planes(np.array([self._action]), self.n_actions,
                                        frames[-1].shape[1:])[0])
        return stack(frames)


class EpisodeMemory:
    """An actor's memory between its decisions: every actor's one rule (torch's and ONNX's).

    ``observe`` turns each camera frame into the network's input: the episode's first frame
    begins the history (after :meth:`begin_episode`, the acting protocol's hook), every later
    one is pushed with the action that led to it, the one the actor chose (:meth:`chose`)
    unless another was carried out (:meth:`carried_out`, an exploring evaluation's).
    """

    def __init__(self, k: int, n_actions: int = 0) -> None:
        """Keep ``k`` frames and, with ``n_actions`` > 0, the previous action's planes."""
        self.history = FrameHistory(k, n_actions)
        self._begun = False
        self._action = NO_ACTION

    @classmethod
    def of(cls, channels: int, frame_channels: int, n_actions: int) -> EpisodeMemory:
        """Return the memory of a network taking ``channels`` input channels.

        ``frame_channels``: one frame's (3); ``n_actions``: the action planes it takes (0 for
        none).  A network of one frame and no planes gets a memory of one frame: the frame
        alone is its input.
        """
        k = (channels - n_actions) // frame_channels
        if k < 1 or k * frame_channels + n_actions != channels:
            raise ValueError(f'{channels} input channels are not k frames of {frame_channels} '
                             f'and {n_actions} action planes')
        return cls(k, n_actions)

    def begin_episode(self) -> None:
        """Start an episode: the next frame begins the history."""
        self._begun = False

    def observe(self, frame: np.ndarray) -> np.ndarray:
        """Return the network's input for the episode's latest ``frame``."""
        stacked = (self.history.push(frame, self._action) if self._begun
                   else self.history.begin(frame))
        self._begun = True
        return stacked

    def chose(self, action: int) -> None:
        """Note the action chosen for the latest frame: the next frame's previous action."""
        self._action = int(action)

    carried_out = chose  # an action carried out instead of the chosen one takes its place


class GreedyActor:
    """The greedy actor over its memory: the rule of the checkpoint's actor and the ONNX one.

    A subclass sets ``memory`` (:meth:`EpisodeMemory.of` its network's input) and gives the
    Q-values of one network input (:meth:`q_values`); this class keeps the acting protocol's
    episode hook and chooses argmax Q.
    """

    memory: EpisodeMemory

    def q_values(self, network_input: np.ndarray) -> np.ndarray:
        """Return the network's Q-values for one input (a frame, or a memory's stack)."""
        raise NotImplementedError

    def begin_episode(self, seed: int | None) -> None:
        """Start an episode: the memory begins again at the next observation."""
        self.memory.begin_episode()

    def carried_out(self, action: int) -> None:
        """Note the action carried out instead of the greedy one: the memory's previous action."""
        self.memory.carried_out(action)

    def act(self, observation: np.ndarray) -> tuple[int, tuple[float, ...]]:
        """Return argmax Q of one (3, 84, 84) frame (with the memory's) and the Q-values."""
        q_values = self.q_values(self.memory.observe(observation))
        action = int(np.argmax(q_values))
        self.memory.chose(action)
        return action, tuple(round(float(q), 6) for q in q_values)


def history_positions(positions: np.ndarray, k: int, size: int,
                      begins: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Return the buffer positions of each position's frame stack: ``(len(positions), k)``.

    Column ``k - 1`` is the position itself, and each column before it the position before,
    modulo the buffer's ``size``, until a frame that ``begins`` an episode: that frame then
    stands in for the rest, as :class:`FrameHistory` pads.  ``begins(q)`` tells for an array of
    positions whether the frame there begins an episode; a replay buffer says so where the
    transition before it ended one, and at its oldest frame (nothing before that is kept).
    """
    positions = np.asarray(positions, dtype=np.int64)
    out = np.empty((len(positions), k), dtype=np.int64)
    current = positions.copy()
    out[:, k - 1] = current
    stopped = np.asarray(begins(current), dtype=bool)
    for column in range(k - 2, -1, -1):
        current = np.where(stopped, current, (current - 1) % size)
        out[:, column] = current
        stopped = stopped | np.asarray(begins(current), dtype=bool)
    return out
