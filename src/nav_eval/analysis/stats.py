"""Statistics of a sweep with rliable (pure: numpy, scipy and rliable; no ROS, no Ray).

Scores are rates in [0, 1] arranged as rliable expects: a matrix of ``runs x tasks`` (here one
task, e.g. the held-out bank, so ``(seeds, 1)``), or ``runs x tasks x checkpoints`` for a
sample-efficiency curve.  Interval estimates are rliable's stratified bootstrap, percentile
method, 95 %.  rliable draws its resamples from NumPy's *global* generator (its ``random_state``
argument does not reach ``np.random.choice``), so every call here seeds that generator with a
fixed value and restores its previous state afterwards: the same scores always give the same
intervals.

The bootstrap calls the aggregate once per resample (10,000 times per estimate), and rliable's
``aggregate_iqm`` goes through ``scipy.stats.trim_mean``, whose argument handling costs about
0.2 ms a call: :func:`iqm` is the same 25 % trimmed mean over all scores in plain NumPy (equal
to rliable's up to float rounding; ``test_stats`` checks it), which makes a sweep's
statistics several times faster.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
from rliable import library as rly
from rliable import metrics as rlm

from nav_sim.core.events import OUTCOME_SUCCESS

RANDOM_STATE = 2021
REPS = 10_000
CONFIDENCE = 0.95
TRIM = 0.25  # the interquartile mean drops the lowest and highest quarter of the scores


def iqm(scores: np.ndarray) -> float:
    """Return the interquartile mean of all scores (rliable's ``aggregate_iqm``)."""
    return float(iqm_columns(np.ravel(scores)[:, None])[0])


def iqm_columns(scores: np.ndarray) -> np.ndarray:
    """Return the interquartile mean of each column of a ``(scores, columns)`` matrix.

    A column with a NaN is NaN (as ``scipy.stats.trim_mean``; sorting alone would trim it).
    """
    ordered = np.sort(scores, axis=0)
    cut = int(TRIM * ordered.shape[0])  # scipy.stats.trim_mean's cut
    out = ordered[cut:ordered.shape[0] - cut].mean(axis=0)
    return np.where(np.isnan(scores).any(axis=0), np.nan, out)


AGGREGATES: dict[str, Callable[[np.ndarray], float]] = {
    'IQM': iqm, 'mean': rlm.aggregate_mean,
    'median': lambda x: float(np.median(x)), 'optimality gap': rlm.aggregate_optimality_gap}
# For a rate where lower is better (collisions) the optimality gap is the gap to 0: that of
# 1 - rate.  The other aggregates keep the rate's own scale.
LOWER_IS_BETTER = frozenset({'collision_rate', 'timeout_rate'})


@contextlib.contextmanager
def seeded(seed: int = RANDOM_STATE) -> Iterator[None]:
    """Seed NumPy's global generator for rliable, then restore its previous state."""
    saved = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(saved)


def score_matrix(values: Sequence[float]) -> np.ndarray:
    """Turn one score per run into rliable's ``(runs, 1)`` matrix."""
    array = np.asarray(values, dtype=float).reshape(-1, 1)
    if array.size == 0:
        raise ValueError('no scores: at least one run is needed')
    return array


def _estimate(point: Any, interval: np.ndarray) -> dict[str, float]:
    low, high = np.ravel(interval)
    return {'point': float(np.ravel(point)[0]), 'low': float(low), 'high': float(high)}


def aggregate_estimates(scores: Mapping[str, np.ndarray], metric: str = 'success_rate',
                        reps: int = REPS, seed: int = RANDOM_STATE,
                        ) -> dict[str, dict[str, dict[str, float]]]:
    """Compute IQM, mean, median and optimality gap with CIs: ``{key: {aggregate: estimate}}``.

    The median is over all scores (runs): rliable's ``aggregate_median`` is the median over
    *tasks* of per-task means, which for one task is the mean.  ``metric`` names what the
    scores are; for a lower-is-better rate the optimality gap is computed on ``1 - score``
    (distance to 0).
    """
    flip = metric in LOWER_IS_BETTER

    def aggregates(x: np.ndarray) -> np.ndarray:
        gap = rlm.aggregate_optimality_gap(1.0 - x if flip else x)
        return np.array([iqm(x), rlm.aggregate_mean(x), np.median(x), gap])

    with seeded(seed):
        points, intervals = rly.get_interval_estimates(
            dict(scores), aggregates, method='percentile', reps=reps,
            confidence_interval_size=CONFIDENCE)
    return {key: {name: _estimate(points[key][i], intervals[key][:, i])
                  for i, name in enumerate(AGGREGATES)} for key in scores}


def mean_estimates(scores: Mapping[str, np.ndarray], reps: int = REPS,
                   seed: int = RANDOM_STATE) -> dict[str, dict[str, float]]:
    """Compute the mean with its CI per key (e.g. per-episode outcomes of one policy)."""
    with seeded(seed):
        points, intervals = rly.get_interval_estimates(
            dict(scores), lambda x: np.array([rlm.aggregate_mean(x)]), method='percentile',
            reps=reps, confidence_interval_size=CONFIDENCE)
    return {key: _estimate(points[key][0], intervals[key][:, 0]) for key in scores}


def iqm_curve(scores: Mapping[str, np.ndarray], reps: int = REPS, seed: int = RANDOM_STATE,
              ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Compute the IQM with its CI at every checkpoint of ``(runs, tasks, checkpoints)`` scores.

    Returns rliable's point estimates (one per checkpoint) and intervals (``2 x checkpoints``).
    """
    def iqm_per_checkpoint(x: np.ndarray) -> np.ndarray:
        return iqm_columns(x.reshape(-1, x.shape[-1]))

    with seeded(seed):
        return rly.get_interval_estimates(dict(scores), iqm_per_checkpoint, method='percentile',
                                          reps=reps, confidence_interval_size=CONFIDENCE)


def performance_profile(scores: Mapping[str, np.ndarray], taus: np.ndarray, reps: int = 2_000,
                        seed: int = RANDOM_STATE,
                        ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Compute the score distribution (fraction of runs above each tau) with its CIs."""
    with seeded(seed):
        return rly.create_performance_profile(dict(scores), taus, reps=reps,
                                              confidence_interval_size=CONFIDENCE)


#: how a pair's key reads, 'X > Y' (a configuration's name may hold commas: "a=1, b=2")
PAIR_SEPARATOR = ' > '


def improvement_pairs(keys: Sequence[str]) -> list[tuple[str, str]]:
    """Return every ordered pair (X, Y) of different configurations, X before Y."""
    return list(itertools.permutations(keys, 2))


def probability_of_improvement(scores: Mapping[str, np.ndarray], reps: int = 2_000,
                               seed: int = RANDOM_STATE) -> dict[str, dict[str, float]]:
    """Compute P(X > Y) with its CI for every ordered pair: ``{'X > Y': estimate}``."""
    pairs = {f'{x}{PAIR_SEPARATOR}{y}': [scores[x], scores[y]]
             for x, y in improvement_pairs(list(scores))}
    if not pairs:
        return {}
    with seeded(seed):
        points, intervals = rly.get_interval_estimates(
            pairs, rlm.probability_of_improvement, method='percentile', reps=reps,
            confidence_interval_size=CONFIDENCE)
    return {key: _estimate(points[key], intervals[key]) for key in pairs}


def outcome_scores(episodes: Sequence[Mapping[str, Any]], outcome: str = OUTCOME_SUCCESS,
                   ) -> np.ndarray:
    """Turn episodes into a ``(episodes, 1)`` matrix of 1 (this outcome) / 0 (another)."""
    return score_matrix([1.0 if e['outcome'] == outcome else 0.0 for e in episodes])


def bank_verdict(rows: Sequence[Mapping[str, Any]]) -> str:
    """Say whether the held-out bank looks easier than the training bank for every policy.

    ``rows`` have ``policy``, ``train`` and ``heldout`` success estimates.  Easier for every
    policy is what separate distributions look like (the issue's test); otherwise the banks
    are compatible with one distribution as far as these policies can tell.
    """
    if not rows:
        return 'no policy was evaluated on both banks'
    easier = [r['heldout']['point'] > r['train']['point'] for r in rows]
    apart = [r['heldout']['low'] > r['train']['high'] or r['train']['low'] > r['heldout']['high']
             for r in rows]
    if all(easier):
        return ('the held-out bank is easier than the training bank for every policy: the banks '
                'do not look drawn from one distribution')
    if any(apart):
        return ('the banks differ for some policy (non-overlapping CIs) but the held-out bank '
                'is not easier for every policy')
    return ('the held-out bank is not easier for every policy and every CI overlaps: no '
            'evidence that the banks differ in difficulty')
