"""The agent's frame history: acting and replay rebuild the same stacks (issue 30)."""

from __future__ import annotations

import numpy as np
import pytest

from nav_gym.policy.history import FrameHistory, history_positions, stack


def frame(value: int) -> np.ndarray:
    return np.full((3, 2, 2), value, np.uint8)


def test_an_episode_starts_padded_with_its_first_frame_and_slides():
    history = FrameHistory(3)
    first = history.begin(frame(1))
    assert first.shape == (9, 2, 2) and set(first.reshape(3, -1)[:, 0]) == {1}
    history.push(frame(2))
    latest = history.push(frame(3))
    assert np.array_equal(latest, stack([frame(1), frame(2), frame(3)]))
    assert np.array_equal(history.push(frame(4)), stack([frame(2), frame(3), frame(4)]))
    assert np.array_equal(history.begin(frame(9)), stack([frame(9)] * 3))  # a new episode
    assert np.array_equal(FrameHistory(1).begin(frame(5)), frame(5))  # k 1: no memory
    with pytest.raises(RuntimeError, match='begin'):
        FrameHistory(2).push(frame(1))
    with pytest.raises(ValueError):
        FrameHistory(0)


@pytest.mark.parametrize('k', [1, 2, 4])
@pytest.mark.parametrize('size', [7, 50])
def test_the_replay_buffer_rebuilds_the_stacks_acting_saw(k, size):
    """The stacks a circular buffer rebuilds are the ones acting saw.

    Episodes of random lengths (time-outs and terminations alike) through a buffer that wraps
    several times: every stack whose frames are all still kept is the acting one; at the oldest
    kept frame the stack is padded, as at an episode's start.
    """
    rng = np.random.default_rng(k * 100 + size)
    frames = np.zeros((size, 3, 2, 2), np.uint8)
    dones = np.zeros(size, bool)  # the transition stored at a position ended its episode
    acting: dict[int, np.ndarray] = {}  # the stack acting saw, by the time step written
    begun: dict[int, int] = {}  # the first time step of each time step's episode
    written = np.full(size, -1)  # the time step whose frame a position holds
    history, t, left, start = FrameHistory(k), 0, 0, 0
    for t in range(4 * size + 3):
        value = t % 251 + 1
        if left == 0:
            observation = history.begin(frame(value))
            left, start = int(rng.integers(1, 6)), t
        else:
            observation = history.push(frame(value))
        left -= 1
        position = t % size
        frames[position], dones[position], written[position] = frame(value), left == 0, t
        acting[t], begun[t] = observation, start
    newest = t
    oldest_position = (newest + 1) % size

    def begins(q: np.ndarray) -> np.ndarray:
        return (q == oldest_position) | dones[(q - 1) % size]

    positions = np.arange(size)
    rebuilt = history_positions(positions, k, size, begins)
    for position, row in zip(positions, rebuilt, strict=True):
        step = written[position]
        replayed = stack([frames[q] for q in row])
        oldest_step = newest - size + 1
        if max(begun[step], step - k + 1) >= oldest_step:  # every frame it needs is kept
            assert np.array_equal(replayed, acting[step]), (position, row)
        else:  # reaches behind the oldest kept frame: padded with that frame
            assert row[0] == oldest_position or dones[(row[0] - 1) % size]


def test_the_previous_action_follows_the_frames_as_one_hot_planes():
    from nav_gym.policy.history import NO_ACTION, action_planes
    planes = action_planes(np.array([2, NO_ACTION, 0]), 3, (2, 2))
    assert planes.shape == (3, 3, 2, 2) and planes.dtype == np.uint8
    assert [list(p[:, 0, 0]) for p in planes] == [[0, 0, 255], [0, 0, 0], [255, 0, 0]]
    history = FrameHistory(2, n_actions=3)
    first = history.begin(frame(1))
    assert first.shape == (9, 2, 2) and not first[6:].any()  # no action yet
    after = history.push(frame(2), 1)
    assert np.array_equal(after[:6], stack([frame(1), frame(2)]))
    assert list(after[6:, 0, 0]) == [0, 255, 0]
    assert not history.begin(frame(3))[6:].any()  # a new episode: none again
