"""Metrics on constructed episodes, including SPL edge cases."""

from __future__ import annotations

import csv
import io

import pytest

from nav_eval.analysis import metrics
from nav_eval.analysis.metrics import episode_result, outcome_of, spl, summarize


def test_spl_is_habitat_definition():
    assert spl(True, 1.0, 1.0) == 1.0
    assert spl(True, 1.0, 2.0) == pytest.approx(0.5)
    assert spl(True, 1.0, 0.9) == 1.0          # stopped 10 cm short of the centre: capped
    assert spl(False, 1.0, 1.0) == 0.0         # failures score 0 however short the path
    assert spl(True, 0.0, 0.0) == 1.0          # nothing to travel
    assert spl(True, 0.0, 0.5) == 1.0


@pytest.mark.parametrize('shortest, path', [(-1.0, 1.0), (1.0, -0.1), (float('nan'), 1.0),
                                            (1.0, float('inf'))])
def test_spl_rejects_impossible_lengths(shortest, path):
    with pytest.raises(ValueError, match='SPL'):
        spl(True, shortest, path)


def test_outcomes():
    assert outcome_of('goal', False) == 'success'
    assert outcome_of('collision', False) == 'collision'
    assert outcome_of('none', True) == 'timeout'
    assert outcome_of('goal', True) == 'success'  # a goal on the last step is a success
    with pytest.raises(ValueError):
        outcome_of('none', False)


def _episodes():
    return [
        episode_result(101, 'train', 'goal', False, 40, 4.9, 1.0, 0.08, 1.25),
        episode_result(102, 'train', 'collision', False, 12, -1.2, 0.8, 0.7, 0.3),
        episode_result(103, 'train', 'none', True, 250, -2.4, 0.9, 1.1, 2.0),
        episode_result(104, 'train', 'goal', False, 30, 5.3, 0.7, 0.09, 0.7),
    ]


def test_summary_rates_and_means():
    s = summarize(_episodes())
    assert (s.episodes, s.success_rate, s.collision_rate, s.timeout_rate) == (4, 0.5, 0.25,
                                                                               0.25)
    assert s.mean_length == pytest.approx((40 + 12 + 250 + 30) / 4)
    assert s.mean_spl == pytest.approx((1.0 / 1.25 + 0 + 0 + 1.0) / 4)
    assert s.mean_return == pytest.approx((4.9 - 1.2 - 2.4 + 5.3) / 4)
    with pytest.raises(ValueError, match='empty'):
        summarize([])


def test_table_and_csv():
    s = summarize(_episodes())
    table = metrics.markdown_table(metrics.TABLE_COLUMNS, [metrics.summary_row('DQN', s)])
    assert '| DQN | 4 | 50% | 25% | 25% | 83.0 | 0.450 | 1.650 |' in table
    text = metrics.episodes_csv([('dqn', [e.to_dict() for e in _episodes()])])
    rows = list(csv.DictReader(io.StringIO(text)))
    assert [r['outcome'] for r in rows] == ['success', 'collision', 'timeout', 'success']
    assert rows[0]['set'] == 'dqn' and float(rows[0]['spl']) == pytest.approx(0.8)
    assert float(rows[2]['return']) == pytest.approx(-2.4)
