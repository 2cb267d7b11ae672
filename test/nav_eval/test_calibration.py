"""The value calibration of evaluated episodes, on constructed traces (no ROS)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nav_eval import calibration
from nav_gym import run_dir as layout


def trace(seed: int, outcome: str, steps: list[tuple[int, list[float] | None, float, float]],
          initial: float = 1.0) -> dict:
    """Return a trace whose steps are (action, Q-values, reward, distance after the step)."""
    return {'seed': seed, 'outcome': outcome, 'scenario': {'initial_distance': initial},
            'steps': [{'action': a, 'q_values': q, 'reward': r, 'distance': d}
                      for a, q, r, d in steps]}


def test_discounted_returns_of_a_finished_episode():
    g = calibration.discounted_returns([1.0, 0.0, 2.0], gamma=0.5)
    assert g == pytest.approx([1.0 + 0.5 * 0.0 + 0.25 * 2.0, 0.0 + 0.5 * 2.0, 2.0])


def test_one_episode_pairs_each_decision_with_its_return_and_distance():
    e = calibration.episode_values(trace(7, 'success', [
        (1, [0.0, 6.0, 1.0], 0.1, 0.5),
        (2, [1.0, 2.0, 5.5], 5.0, 0.08)], initial=0.6), gamma=0.9)
    assert (e.seed, e.outcome) == (7, 'success')
    assert e.q == pytest.approx([6.0, 5.5])  # the value of the action taken, not the max
    assert e.returns == pytest.approx([0.1 + 0.9 * 5.0, 5.0])
    assert e.distance == pytest.approx([0.6, 0.5])  # before each decision


def test_time_outs_and_policies_without_q_values_are_left_out():
    assert calibration.episode_values(trace(1, 'timeout', [(1, [0, 1, 0], 0.0, 1.0)]), 0.9) \
        is None
    assert calibration.episode_values(trace(2, 'success', [(1, None, 5.0, 0.0)]), 0.9) is None


def test_summary_of_a_known_overestimate_near_and_far():
    near = calibration.EpisodeValues(1, 'success', q=np.array([7.0, 6.0]),
                                     returns=np.array([4.0, 5.0]), distance=np.array([0.2, 0.1]))
    far = calibration.EpisodeValues(2, 'collision', q=np.array([1.0]), returns=np.array([-1.0]),
                                    distance=np.array([0.9]))
    out = calibration.summarise([near, far])
    assert (out['episodes'], out['decisions']) == (2, 3)
    assert out['q'] == pytest.approx(14 / 3) and out['return'] == pytest.approx(8 / 3)
    assert out['overestimate'] == pytest.approx(2.0)
    assert out['near'] == pytest.approx(2.0)  # (3 + 1) / 2
    assert out['far'] == pytest.approx(2.0)
    assert calibration.summarise([near])['far'] is None
    assert calibration.summarise([]) is None


def test_a_set_is_read_from_its_traces(tmp_path):
    for seed, outcome in ((201, 'success'), (202, 'timeout'), (203, 'collision')):
        path = layout.trace_path(tmp_path, 'dqn_heldout', seed)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(trace(seed, outcome, [(1, [0.0, 3.0, 0.0], 1.0, 0.5)])))
    bad = layout.trace_path(tmp_path, 'dqn_heldout', 204)
    bad.write_text('{"seed": 204, "outcome": "success"')  # cut short: left out
    layout.trace_path(tmp_path, 'dqn_heldout', 205).write_text('[205]')  # not a trace
    layout.trace_path(tmp_path, 'dqn_heldout', 206).write_text('{"seed": [206]}')  # nor this
    wrong = trace(207, 'success', [(-1, [0.0, 3.0, 0.0], 1.0, 0.5)])  # no such action
    layout.trace_path(tmp_path, 'dqn_heldout', 207).write_text(json.dumps(wrong))
    episodes = calibration.set_values(tmp_path, 'dqn_heldout', gamma=0.99)
    assert [(e.seed, e.outcome) for e in episodes] == [(201, 'success'), (203, 'collision')]
    assert [e.seed for e in calibration.set_values(tmp_path, 'dqn_heldout', 0.99, [203])] == [203]
    assert calibration.set_values(tmp_path, 'dqn_train', 0.99) == []


def test_sweep_rows_per_seed_then_pooled_named_by_their_seeds():
    from nav_eval.sweep_report import _calibration_markdown, calibration_rows

    one = calibration.EpisodeValues(1, 'success', q=np.array([6.0]), returns=np.array([4.0]),
                                    distance=np.array([0.5]))
    two = calibration.EpisodeValues(2, 'collision', q=np.array([2.0]),
                                    returns=np.array([-1.0]), distance=np.array([0.1]))
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
    assert '| c | all | final | 2 | 2 | 4.00 | 1.50 | +2.50 | +3.00 | +2.00 |' in text
    assert '| c | 1 | 20000 | 1 | 1 | 6.00 | 4.00 | +2.00 | – | +2.00 |' in text
    assert 'No held-out episode' in '\n'.join(_calibration_markdown([]))
