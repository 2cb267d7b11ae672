"""The value calibration of evaluated episodes, on constructed traces (no ROS)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from nav_eval.analysis import calibration
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import trace_path

WORKSHOP = TrainConfig()  # gamma 0.99, goal +5, 2 per metre of progress, -0.01 a step, -1


def reward(gamma: float) -> SimpleNamespace:
    """Return the workshop's reward weights with another discount."""
    return SimpleNamespace(gamma=gamma, goal_reward=5.0, progress_weight=2.0,
                           step_penalty=-0.01, collision_penalty=-1.0)


def trace(seed: int, outcome: str, steps: list[tuple[int, list[float] | None, float, float]],
          initial: float = 1.0) -> dict:
    """Return a trace whose steps are (action, Q-values, reward, distance after the step)."""
    return {'seed': seed, 'outcome': outcome, 'scenario': {'initial_distance': initial},
            'steps': [{'action': a, 'q_values': q, 'reward': r, 'distance': d}
                      for a, q, r, d in steps]}


def values(seed: int, outcome: str, q: list[float], returns: list[float] | None,
           distance: list[float]) -> calibration.EpisodeValues:
    """Return an episode's values with the workshop's bound."""
    return calibration.EpisodeValues(
        seed, outcome, q=np.array(q), returns=None if returns is None else np.array(returns),
        distance=np.array(distance), bound=calibration.return_bound(np.array(distance), WORKSHOP))


def test_discounted_returns_of_a_finished_episode():
    g = calibration.discounted_returns([1.0, 0.0, 2.0], gamma=0.5)
    assert g == pytest.approx([1.0 + 0.5 * 0.0 + 0.25 * 2.0, 0.0 + 0.5 * 2.0, 2.0])


def test_the_bound_is_the_goal_bonus_and_the_progress_of_the_whole_distance():
    assert calibration.return_bound(np.array([0.0, 1.5]), WORKSHOP) == pytest.approx([5.0, 8.0])
    generous = SimpleNamespace(gamma=0.9, goal_reward=1.0, progress_weight=1.0,
                               step_penalty=0.1, collision_penalty=0.5)  # pays to live and hit
    assert calibration.return_bound(np.array([2.0]), generous) == pytest.approx([1 + .5 + 1 + 2])


def test_no_path_returns_more_than_the_bound():
    rng = np.random.default_rng(0)
    for _ in range(200):  # random walks toward and away from the goal, ending at it
        distance = np.concatenate([rng.uniform(0.1, 2.5, size=rng.integers(1, 40)), [0.05]])
        start = float(rng.uniform(0.6, 2.5))
        before = np.concatenate([[start], distance[:-1]])
        rewards = 2.0 * (before - distance) - 0.01
        rewards[-1] += 5.0
        g = calibration.discounted_returns(rewards, WORKSHOP.gamma)
        assert np.all(g <= calibration.return_bound(before, WORKSHOP) + 1e-12)


def test_one_episode_pairs_each_decision_with_its_return_distance_and_bound():
    e = calibration.episode_values(trace(7, 'success', [
        (1, [0.0, 6.0, 1.0], 0.1, 0.5),
        (2, [1.0, 2.0, 5.5], 5.0, 0.08)], initial=0.6), reward(0.9))
    assert (e.seed, e.outcome) == (7, 'success')
    assert e.q == pytest.approx([6.0, 5.5])  # the value of the action taken, not the max
    assert e.returns == pytest.approx([0.1 + 0.9 * 5.0, 5.0])
    assert e.distance == pytest.approx([0.6, 0.5])  # before each decision
    assert e.bound == pytest.approx([6.2, 6.0])


def test_a_time_out_has_no_returns_and_a_policy_without_q_values_is_left_out():
    e = calibration.episode_values(trace(1, 'timeout', [(1, [0, 9, 0], 0.0, 1.0)]), WORKSHOP)
    assert e.returns is None and e.q == pytest.approx([9.0])
    assert calibration.episode_values(trace(2, 'success', [(1, None, 5.0, 0.0)]), WORKSHOP) \
        is None


def test_summary_of_a_known_overestimate_near_and_far_and_above_the_bound():
    near = values(1, 'success', [7.0, 6.0], [4.0, 5.0], [0.2, 0.1])
    far = values(2, 'collision', [1.0], [-1.0], [0.9])
    late = values(3, 'timeout', [7.0, 6.0], None, [0.5, 0.4])  # bounds 6.0, 5.8
    out = calibration.summarise([near, far, late])
    assert (out['episodes'], out['decisions']) == (2, 3)  # the episodes that ended
    assert out['q'] == pytest.approx(14 / 3) and out['return'] == pytest.approx(8 / 3)
    assert out['overestimate'] == pytest.approx(2.0)
    assert out['near'] == pytest.approx(2.0)  # (3 + 1) / 2
    assert out['far'] == pytest.approx(2.0)
    # every decision: 7 > 5.4 and 6 > 5.2 (near), 1 < 6.8, 7 > 6.0 and 6 > 5.8 (the time-out)
    assert (out['all_decisions'], out['above_bound']) == (5, pytest.approx(4 / 5))
    assert calibration.summarise([near])['far'] is None
    only_late = calibration.summarise([late])
    assert only_late['episodes'] == 0 and only_late['q'] is None
    assert only_late['above_bound'] == pytest.approx(1.0)
    assert calibration.summarise([]) is None


def test_a_set_is_read_from_its_traces(tmp_path):
    for seed, outcome in ((201, 'success'), (202, 'timeout'), (203, 'collision')):
        path = trace_path(tmp_path, 'dqn_heldout', seed)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(trace(seed, outcome, [(1, [0.0, 3.0, 0.0], 1.0, 0.5)])))
    bad = trace_path(tmp_path, 'dqn_heldout', 204)
    bad.write_text('{"seed": 204, "outcome": "success"')  # cut short: left out
    trace_path(tmp_path, 'dqn_heldout', 205).write_text('[205]')  # not a trace
    trace_path(tmp_path, 'dqn_heldout', 206).write_text('{"seed": [206]}')  # nor this
    wrong = trace(207, 'success', [(-1, [0.0, 3.0, 0.0], 1.0, 0.5)])  # no such action
    trace_path(tmp_path, 'dqn_heldout', 207).write_text(json.dumps(wrong))
    episodes = calibration.set_values(tmp_path, 'dqn_heldout', WORKSHOP)
    assert [(e.seed, e.outcome) for e in episodes] == [
        (201, 'success'), (202, 'timeout'), (203, 'collision')]
    assert [e.seed for e in calibration.set_values(tmp_path, 'dqn_heldout', WORKSHOP, [203])] \
        == [203]
    assert calibration.set_values(tmp_path, 'dqn_train', WORKSHOP) == []


def test_sweep_rows_per_seed_then_pooled_named_by_their_seeds():
    from nav_eval.sweeps.report import _calibration_markdown
    from nav_eval.sweeps.statistics import calibration_rows

    one = values(1, 'success', [6.0], [4.0], [0.5])
    two = values(2, 'collision', [2.0], [-1.0], [0.1])
    members = [{'seed': 1, 'values': [one], 'curve_values': {10000: [one], 20000: [one]}},
               {'seed': 2, 'values': [two], 'curve_values': {10000: [two], 20000: []}},
               {'seed': 3, 'values': [], 'curve_values': {}}]  # kept no traces
    rows = calibration_rows({'c': members})
    assert [(r['seed'], r['steps']) for r in rows] == [
        (1, None), (2, None), ('1, 2', None), ('1, 2', 10000), (1, 20000)]
    assert rows[2]['overestimate'] == pytest.approx(2.5)  # (6 - 4 + 2 + 1) / 2
    rows = calibration_rows({'c': members[:2]})  # every seed in the pool: 'all'
    assert [r['seed'] for r in rows] == [1, 2, 'all', 'all', 1]
    text = '\n'.join(_calibration_markdown(rows))
    # 6 > 6.0 is not above the bound, 2 < 5.2 neither
    assert '| c | all | final | 2 | 2 | 4.00 | 1.50 | +2.50 | +3.00 | +2.00 | 0% of 2 |' in text
    assert '| c | 1 | 20000 | 1 | 1 | 6.00 | 4.00 | +2.00 | – | +2.00 | 0% of 1 |' in text
    assert 'No held-out episode' in '\n'.join(_calibration_markdown([]))
