"""Sweep statistics on constructed score matrices (rliable; no ROS, no Ray)."""

from __future__ import annotations

import numpy as np
import pytest

from nav_eval.analysis import stats

REPS = 2_000  # enough for these checks, cheap on a loaded machine


def test_iqm_of_known_values():
    # 8 runs: IQM drops the lowest 2 and highest 2 and averages the middle 4
    scores = {'a': stats.score_matrix([0.0, 0.1, 0.5, 0.6, 0.7, 0.8, 0.95, 1.0])}
    est = stats.aggregate_estimates(scores, reps=REPS)['a']
    assert est['IQM']['point'] == pytest.approx((0.5 + 0.6 + 0.7 + 0.8) / 4)
    assert est['mean']['point'] == pytest.approx(np.mean([0.0, 0.1, 0.5, 0.6, 0.7, 0.8, 0.95,
                                                          1.0]))
    assert est['median']['point'] == pytest.approx(0.65)
    assert est['optimality gap']['point'] == pytest.approx(1 - est['mean']['point'])


@pytest.mark.parametrize('runs', [1, 2, 3, 4, 5, 7, 10, 101])
def test_iqm_is_rliables_iqm(runs):
    from rliable import metrics
    rng = np.random.default_rng(runs)
    scores = rng.uniform(0.0, 1.0, size=(runs, 3))
    assert stats.iqm(scores) == pytest.approx(metrics.aggregate_iqm(scores), abs=1e-12)
    curve = rng.uniform(0.0, 1.0, size=(runs, 1, 4))  # runs x tasks x checkpoints
    expected = [metrics.aggregate_iqm(curve[..., i]) for i in range(4)]
    assert stats.iqm_columns(curve.reshape(-1, 4)) == pytest.approx(expected, abs=1e-12)
    scores[0, 0] = np.nan  # rliable (scipy) passes a NaN through instead of trimming it
    assert np.isnan(stats.iqm(scores)) and np.isnan(metrics.aggregate_iqm(scores))


def test_collision_optimality_gap_is_the_gap_to_zero():
    est = stats.aggregate_estimates({'a': stats.score_matrix([0.0, 0.1, 0.2])},
                                    'collision_rate', reps=REPS)['a']
    assert est['optimality gap']['point'] == pytest.approx(0.1)  # mean collisions above 0


@pytest.mark.parametrize('values', [[0.2, 0.9, 0.5, 0.7, 0.8], [0.9, 0.95, 1.0], [0.1] * 4])
def test_intervals_contain_the_point_estimate(values):
    est = stats.aggregate_estimates({'a': stats.score_matrix(values)}, reps=REPS)['a']
    for name, e in est.items():
        assert e['low'] - 1e-12 <= e['point'] <= e['high'] + 1e-12, name


def test_intervals_narrow_with_more_runs():
    rng = np.random.default_rng(0)
    few = rng.uniform(0.5, 1.0, size=5)
    many = rng.uniform(0.5, 1.0, size=200)
    widths = {}
    for key, values in (('few', few), ('many', many)):
        e = stats.aggregate_estimates({key: stats.score_matrix(values)}, reps=REPS)[key]['IQM']
        widths[key] = e['high'] - e['low']
    assert widths['many'] < widths['few'] / 3


def test_same_random_state_same_results_and_the_global_generator_is_untouched():
    rng = np.random.default_rng(1)
    scores = {'a': stats.score_matrix(rng.uniform(size=30)),
              'b': stats.score_matrix(rng.uniform(size=20))}
    np.random.seed(123)
    before = np.random.get_state()[1].copy()
    first = stats.aggregate_estimates(scores, reps=REPS)
    assert (np.random.get_state()[1] == before).all()
    np.random.rand(10)  # whatever else used the global generator in between
    assert stats.aggregate_estimates(scores, reps=REPS) == first
    other = stats.aggregate_estimates(scores, reps=REPS, seed=7)
    assert other != first  # the seed is what fixes the intervals


def test_probability_of_improvement_and_bank_estimates():
    better, worse = stats.score_matrix([0.8, 0.9, 0.85]), stats.score_matrix([0.2, 0.3, 0.25])
    poi = stats.probability_of_improvement({'x': better, 'y': worse}, reps=REPS)
    assert poi['x > y']['point'] == pytest.approx(1.0)
    assert poi['y > x']['point'] == pytest.approx(0.0)
    episodes = [{'outcome': 'success'}] * 3 + [{'outcome': 'collision'}]
    bank = stats.mean_estimates({'train': stats.outcome_scores(episodes)}, reps=REPS)['train']
    assert bank['point'] == pytest.approx(0.75) and bank['low'] <= 0.75 <= bank['high']


def test_configuration_names_with_commas_keep_their_pairs_and_figure(tmp_path):
    # a grid over worlds names configurations by every setting that differs: "a=1, b=2"
    from nav_eval.sweeps.figures import write_figures
    scores = {'max_episode_steps=120, world=clutter.xml': stats.score_matrix([0.9, 0.95]),
              'max_episode_steps=200, world=rooms.xml': stats.score_matrix([0.6, 0.7])}
    improvement = stats.probability_of_improvement(scores, reps=200)
    assert set(improvement) == {
        'max_episode_steps=120, world=clutter.xml > max_episode_steps=200, world=rooms.xml',
        'max_episode_steps=200, world=rooms.xml > max_episode_steps=120, world=clutter.xml'}
    figures = write_figures(tmp_path, {'aggregates': {}, 'improvement': improvement}, scores, {})
    assert (tmp_path / figures['improvement']).is_file()


def test_bank_verdict():
    def est(p):
        return {'point': p, 'low': p - 0.05, 'high': p + 0.05}
    easier = [{'policy': 'random', 'train': est(0.1), 'heldout': est(0.2)},
              {'policy': 'servo', 'train': est(0.6), 'heldout': est(0.7)}]
    assert 'easier than the training bank for every policy' in stats.bank_verdict(easier)
    mixed = [easier[0], {'policy': 'servo', 'train': est(0.7), 'heldout': est(0.68)}]
    assert 'no evidence' in stats.bank_verdict(mixed)


def test_no_scores_is_a_clear_error():
    with pytest.raises(ValueError, match='at least one run'):
        stats.score_matrix([])
