"""The failure anatomy of evaluated episodes, on constructed traces (no ROS)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nav_eval.analysis import anatomy
from nav_gym.training.run_dir import frames_path, read_traces, trace_path

L, F, R = 0, 1, 2


def frames_with_goal(seen: list[bool], pixels: int = 25) -> np.ndarray:
    """Black observations; a green block of ``pixels`` pixels where ``seen``."""
    frames = np.zeros((len(seen), 3, 84, 84), np.uint8)
    side = int(pixels ** 0.5)
    for i, s in enumerate(seen):
        if s:
            frames[i, 1, 40:40 + side, 40:40 + side] = 200
    return frames


def trace(seed: int, outcome: str, actions: list[int]) -> dict:
    return {'seed': seed, 'outcome': outcome, 'steps': [{'action': a} for a in actions]}


def test_one_episode():
    actions = [L, R, L, R, F, R, F, F]
    seen = [False, False, False, True, True, True, False, True, True]  # + the last observation
    e = anatomy.episode_anatomy(trace(7, 'timeout', actions), frames_with_goal(seen))
    assert (e.seed, e.outcome, e.decisions) == (7, 'timeout', 8)
    assert e.first_in_view == 3
    assert e.in_view == 4  # decisions 3, 4, 5 and 7 (the final observation is no decision)
    assert e.forward_in_view == 2  # decisions 4 and 7
    assert e.reversals == 3  # L R, R L, L R (R F, F R are not reversals)


def test_a_few_green_pixels_are_not_the_goal_and_never_seen_is_none():
    e = anatomy.episode_anatomy(trace(1, 'timeout', [L, L]),
                                frames_with_goal([True, True, True], pixels=4))
    assert e.first_in_view is None and e.in_view == 0


def test_summary_per_outcome():
    eps = [anatomy.EpisodeAnatomy(1, 'success', 10, 0, 8, 4, 2),
           anatomy.EpisodeAnatomy(2, 'success', 30, 4, 20, 10, 6),
           anatomy.EpisodeAnatomy(3, 'timeout', 100, 60, 30, 3, 50),
           anatomy.EpisodeAnatomy(4, 'timeout', 100, None, 0, 0, 70)]
    out = anatomy.summarise(eps)
    assert list(out) == ['success', 'timeout']
    assert out['success']['median_first_in_view'] == 2
    assert out['success']['in_view_share'] == pytest.approx(28 / 40)
    assert out['success']['forward_in_view'] == pytest.approx(14 / 28)
    assert out['timeout']['median_first_in_view'] == 60
    assert out['timeout']['never_in_view'] == 1
    assert out['timeout']['reversals_per_100'] == pytest.approx(60)


def test_a_set_is_read_from_its_traces(tmp_path):
    for seed, outcome in ((201, 'success'), (202, 'timeout')):
        path = trace_path(tmp_path, 'dqn_heldout', seed)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(trace(seed, outcome, [F, F])))
        np.savez_compressed(frames_path(path), obs=frames_with_goal([True, True, True]))
    eps = anatomy.traces_anatomy(read_traces(tmp_path, 'dqn_heldout'))
    assert [(e.seed, e.outcome, e.in_view) for e in eps] == [(201, 'success', 2),
                                                             (202, 'timeout', 2)]
    assert [e.seed for e in anatomy.traces_anatomy(
        read_traces(tmp_path, 'dqn_heldout', [202, 203]))] == [202]
    assert anatomy.traces_anatomy(read_traces(tmp_path, 'dqn_train')) == []


def test_a_trace_that_says_what_each_decision_saw_needs_no_frames(tmp_path):
    actions = [L, R, L, R, F, R, F, F]
    seen = [False, False, False, True, True, True, False, True, True]
    frames = frames_with_goal(seen)
    flagged = trace(7, 'timeout', actions)
    for step, frame in zip(flagged['steps'], frames, strict=False):
        step['goal_in_view'] = anatomy.goal_in_view(frame)  # as evaluation writes it
    assert [s['goal_in_view'] for s in flagged['steps']] == seen[:-1]
    assert anatomy.episode_anatomy(flagged) == anatomy.episode_anatomy(
        trace(7, 'timeout', actions), frames)
    path = trace_path(tmp_path, 'dqn_heldout', 7)  # a set without frames (a device screen's)
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(flagged))
    assert [(e.seed, e.in_view, e.first_in_view) for e in anatomy.traces_anatomy(
        read_traces(tmp_path, 'dqn_heldout'))] == [(7, 4, 3)]
    path.write_text(json.dumps(trace(7, 'timeout', actions)))  # an older trace needs them
    assert anatomy.traces_anatomy(read_traces(tmp_path, 'dqn_heldout')) == []
    with pytest.raises(ValueError, match='neither goal_in_view nor frames'):
        anatomy.episode_anatomy(trace(7, 'timeout', actions))


def test_frames_that_do_not_match_the_decisions_are_refused():
    with pytest.raises(ValueError, match='3 observations for 3 decisions'):
        anatomy.episode_anatomy(trace(5, 'timeout', [L, F, R]), frames_with_goal([True] * 3))


def test_a_collision_says_where_the_robot_touched_and_whether_it_could_see_it():
    import math

    arena = {'half_size': 1.0, 'robot_radius': 0.037,
             'shapes': [{'name': 'obstacle_0', 'kind': 'cylinder', 'half_x': 0.08,
                         'half_y': 0.08}]}
    scenario = {'obstacles': [{'slot': 0, 'x': 0.3, 'y': 0.0, 'yaw': 0.0}]}

    def collided(yaw: float) -> dict:  # touching the cylinder's left side, facing yaw
        return {'seed': 1, 'outcome': 'collision', 'scenario': scenario,
                'steps': [{'action': 1, 'pose': [0.3 - 0.08 - 0.037, 0.0, yaw]}]}

    ahead = anatomy.hit_bearing(collided(0.0), arena)
    assert ahead == pytest.approx(0.0, abs=math.radians(1.5))  # straight ahead
    side = anatomy.hit_bearing(collided(math.pi / 2), arena)
    assert side == pytest.approx(-math.pi / 2, abs=math.radians(1.5))  # on its right
    wall = {'seed': 2, 'outcome': 'collision', 'scenario': {'obstacles': []},
            'steps': [{'action': 0, 'pose': [-1.0 + 0.037, 0.5, 0.0]}]}  # backed into a wall
    assert abs(anatomy.hit_bearing(wall, arena)) == pytest.approx(math.pi, abs=0.03)
    assert anatomy.hit_bearing({**collided(0.0), 'outcome': 'timeout'}, arena) is None


def test_collisions_out_of_view_are_counted_per_outcome():
    def episode(outcome: str, out_of_view: bool | None) -> anatomy.EpisodeAnatomy:
        return anatomy.EpisodeAnatomy(1, outcome, 10, 2, 5, 3, 1, None, out_of_view)

    summary = anatomy.summarise([episode('collision', True), episode('collision', False),
                                 episode('collision', True), episode('timeout', None)])
    assert summary['collision']['hit_out_of_view'] == 2
    assert summary['timeout']['hit_out_of_view'] is None
    unknown = anatomy.summarise([episode('collision', None)])  # no arena: not known
    assert unknown['collision']['hit_out_of_view'] is None
