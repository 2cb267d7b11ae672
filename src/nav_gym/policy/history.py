"""The agent's memory of its last frames: one definition for acting and for replay (no torch).

A frame stack of ``k`` frames is the latest camera frame and the ``k - 1`` before it in the same
episode, oldest first, concatenated along the channels: ``(3 k, 84, 84)`` uint8 for the env's
``(3, 84, 84)`` frames.  At an episode's start there are no earlier frames: its first frame
stands in for them (as Gymnasium's ``FrameStackObservation`` pads with the reset observation).

Acting keeps the frames in :class:`FrameHistory` (begun at each episode start: the acting
protocol's ``begin_episode``); the replay buffer stores single frames and rebuilds the same
stacks at sample time with :func:`history_positions`, so that its memory does not grow k-fold.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np


def stack(frames: list[np.ndarray]) -> np.ndarray:
    """Concatenate ``(C, H, W)`` frames, oldest first, into one ``(k C, H, W)`` observation."""
    return np.concatenate(frames, axis=0)


class FrameHistory:
    """The last ``k`` frames of the current episode, as acting sees them."""

    def __init__(self, k: int) -> None:
        """Keep ``k`` >= 1 frames (1: the frame alone, no memory)."""
        if k < 1:
            raise ValueError(f'a frame history holds at least 1 frame, got {k}')
        self.k = k
        self._frames: deque[np.ndarray] = deque(maxlen=k)

    def begin(self, frame: np.ndarray) -> np.ndarray:
        """Start an episode with its first frame; return the first stacked observation."""
        self._frames.clear()
        self._frames.extend([frame] * self.k)
        return self.observation()

    def push(self, frame: np.ndarray) -> np.ndarray:
        """Add the latest frame of the episode; return the stacked observation."""
        if not self._frames:
            raise RuntimeError('push before begin: an episode starts with begin(first frame)')
        self._frames.append(frame)
        return self.observation()

    def observation(self) -> np.ndarray:
        """Return the stack of the last ``k`` frames, oldest first."""
        return stack(list(self._frames))


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
