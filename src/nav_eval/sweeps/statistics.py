"""A sweep's statistics: per-seed rows, aggregates, curves, banks, anatomy, calibration, looks."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.analysis import anatomy, calibration, looks, stats
from nav_eval.errors import SweepError
from nav_eval.sweeps.collect import (
    FINAL_SETS,
    RATES,
    exported_dirs,
    group_trials,
    missing_line,
    read_exported,
    read_trial,
    trial_configs,
    trial_dirs,
)
from nav_eval.sweeps.spec import (
    BASELINES,
    FAILED_FILE,
    SWEEP_FILE,
    read_json,
)
from nav_sim.core.config import HELDOUT


def _scenarios(points: Any) -> set[tuple[int, ...]]:
    """Return the held-out scenarios of curve points: one entry per set, whatever its order."""
    return {tuple(sorted(p['seeds'])) for p in points}


def per_seed_rows(groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return one row per trial: rates and SPL on the training and held-out sets."""
    rows = []
    for config, members in groups.items():
        for t in members:
            row: dict[str, Any] = {'config': config, 'trial': t['name'], 'seed': t['seed'],
                                   'steps': t['steps'], 'wall_clock_s': t['wall_clock_s']}
            for split, entry in t['final'].items():
                for rate in RATES:
                    row[f'{split}_{rate}'] = entry['summary'][rate]
                row[f'{split}_episodes'] = entry['summary']['episodes']
            scenarios = _scenarios(t['curve'].values())
            if len(scenarios) == 1:  # a summary keeps the trial's curve: comparisons pool it
                row['curve'] = {str(s): p['success_rate'] for s, p in t['curve'].items()}
                row['curve_seeds'] = list(scenarios.pop())
            if t.get('looks'):  # counts, so that a comparison of summaries pools them
                row['looks'] = t['looks']
            rows.append(row)
    return rows


def pool_label(seeds: list[Any], members: list[dict]) -> Any:
    """Name a pool of a configuration's trials: 'all' if every member is in it, else its seeds."""
    if len(seeds) == len(members):
        return 'all'
    return seeds[0] if len(seeds) == 1 else ', '.join(map(str, seeds))


def anatomy_rows(groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return the held-out failure anatomy per configuration and seed, then pooled ('all')."""
    rows = []
    for config, members in groups.items():
        pooled = [e for t in members for e in t['anatomy']]
        if not pooled:
            continue
        pools = [(t['seed'], t['anatomy']) for t in members if t['anatomy']]
        label = pool_label([s for s, _ in pools], members)  # a summary's trials keep none
        for seed, episodes in pools + ([(label, pooled)] if len(pools) > 1 else []):
            for outcome, figures in anatomy.summarise(episodes).items():
                rows.append({'config': config, 'seed': seed, 'outcome': outcome, **figures})
    return rows


def look_rows(groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return the held-out outcomes by look per configuration, its trials with looks pooled.

    A row's ``seed`` is 'all' when every trial of the configuration drew looks, else the seeds
    that did; a configuration without drawn looks has no rows.
    """
    out = []
    for config, members in groups.items():
        found = [t for t in members if t.get('looks')]
        if not found:
            continue
        label = pool_label([t['seed'] for t in found], members)
        for row in looks.rows(looks.add(t['looks'] for t in found)):
            out.append({'config': config, 'seed': label, **row})
    return out


def calibration_rows(groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return the held-out value calibration per configuration and seed, then pooled.

    The final model's rows have ``steps`` None: one per seed with traces, then (with more than
    one) their pool; then one pooled row per checkpoint of the sample-efficiency curve whose
    traces were kept.  A pool's ``seed`` is 'all' when every seed of the configuration is in
    it, else the seed or seeds that are.
    """
    def pool(found: list[tuple[int, list]], members: list[dict]) -> tuple[Any, list]:
        return (pool_label([seed for seed, _ in found], members),
                [e for _, episodes in found for e in episodes])

    rows = []
    for config, members in groups.items():
        found = [(t['seed'], t['values']) for t in members if t['values']]
        pools = found + ([pool(found, members)] if len(found) > 1 else [])
        for seed, episodes in pools:
            rows.append({'config': config, 'seed': seed, 'steps': None,
                         **calibration.summarise(episodes)})
        steps = sorted({s for t in members for s, episodes in t['curve_values'].items()
                        if episodes})
        for step in steps:
            label, pooled = pool([(t['seed'], t['curve_values'][step]) for t in members
                                  if t['curve_values'].get(step)], members)
            rows.append({'config': config, 'seed': label, 'steps': step,
                         **calibration.summarise(pooled)})
    return rows


def configuration_stats(groups: dict[str, list[dict]]) -> dict[str, Any]:
    """Return the rliable aggregates per configuration (held-out success and collisions)."""
    out: dict[str, Any] = {}
    for metric in ('success_rate', 'collision_rate'):
        scores = {c: stats.score_matrix([t['final'][HELDOUT]['summary'][metric]
                                         for t in m if HELDOUT in t['final']])
                  for c, m in groups.items() if any(HELDOUT in t['final'] for t in m)}
        if scores:
            out[metric] = stats.aggregate_estimates(scores, metric)
    return out


def curve_scores(groups: dict[str, list[dict]]) -> dict[str, Any]:
    """Return per configuration the checkpoints every run evaluated and a score matrix.

    A summary's trial counts where its summary kept its curve (older summaries kept none): the
    curve is its configuration's runs' and those trials'.  A line names the summaries' trials
    that it leaves out, and a configuration whose trials evaluated their checkpoints on
    different held-out scenarios gets no curve, with a line that says so.
    """
    out = {}
    for config, everyone in groups.items():
        members = [t for t in everyone if not t['exported'] or t['curve']]
        common = sorted(set.intersection(*(set(t['curve']) for t in members))) if members \
            else []
        if not common:
            continue
        if len(_scenarios(t['curve'][s] for t in members for s in common)) > 1:
            print(f'{config}: no sample-efficiency curve: its trials evaluated their checkpoints '
                  'on different held-out scenarios')
            continue
        if left := [t['name'] for t in everyone if t['exported'] and not t['curve']]:
            print(f"{config}: the sample-efficiency curve leaves out {', '.join(left)} (their "
                  'summaries kept no curve)')
        matrix = np.array([[[t['curve'][s]['success_rate'] for s in common]] for t in members])
        out[config] = {'steps': common, 'scores': matrix,
                       'seeds': members[0]['curve'][common[0]]['seeds']}
    return out


def bank_rows(folder: Path, groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return success on both banks with CIs over scenarios: baselines and the DQN trials."""
    rows = []
    for config in groups:
        baseline = read_json(folder / BASELINES / f'{config}.json') or {}
        by_policy: dict[str, dict[str, list]] = {}
        for s in baseline.get('sets', []):
            by_policy.setdefault(s['policy'], {})[s['split']] = s['episodes']
        dqn = {split: [e for t in groups[config] for e in t['final'].get(split, {})
                       .get('episodes', [])] for split in FINAL_SETS}
        # a summary's trials keep no episodes: a pool without them would be some seeds' only
        if all(dqn.values()) and not any(t['exported'] for t in groups[config]):
            by_policy['DQN final (all seeds pooled)'] = dqn
        for policy, splits in by_policy.items():
            if set(splits) != set(FINAL_SETS):
                continue
            estimates = stats.mean_estimates({split: stats.outcome_scores(splits[split])
                                              for split in FINAL_SETS})
            rows.append({'config': config, 'policy': policy, **estimates,
                         'episodes': {k: len(v) for k, v in splits.items()}})
    return rows


def oracle_gaps(banks: list[dict[str, Any]], aggregates: dict[str, Any]
                ) -> dict[str, dict[str, float]]:
    """Return per configuration the oracle's held-out success, the IQM's and the gap."""
    out = {}
    for row in banks:
        iqm = aggregates.get('success_rate', {}).get(row['config'], {}).get('IQM')
        if row['policy'] == 'oracle' and iqm:
            oracle = row[HELDOUT]['point']
            out[row['config']] = {'oracle': oracle, 'iqm': iqm['point'],
                                  'gap': oracle - iqm['point']}
    return out


def summarise(folder: Path) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """Collect the trials under ``folder`` and compute every figure of the report.

    Returns the report's data (what results.json holds, but for the sample-efficiency
    summary), the held-out success score matrices and the curves (the figures' inputs).
    """
    runs, summaries = trial_dirs(folder), exported_dirs(folder)
    if not runs and not summaries:
        raise SweepError(f'{folder} holds no run directories (trials/*/config.yaml) and no '
                         'sweep summaries (visnav-sweep --export): run a sweep with '
                         '`visnav-sweep` or pass a folder of training runs or summaries')
    spec = read_json(folder / SWEEP_FILE) or {}
    names = trial_configs(folder, spec)
    trials = [read_trial(r) for r in runs] + read_exported(summaries)
    groups = group_trials(trials, names)
    missing = [missing_line(t, folder, spec) for t in trials if len(t['final']) < 2]
    banks = bank_rows(folder, groups)
    data: dict[str, Any] = {
        'configurations': {c: [t['name'] for t in m] for c, m in groups.items()},
        'trials': [t['name'] for t in trials], 'per_seed': per_seed_rows(groups),
        'aggregates': configuration_stats(groups), 'banks': banks,
        'bank_verdict': stats.bank_verdict([r for r in banks]), 'missing': missing,
        'failed': read_json(folder / FAILED_FILE) or {},
        'settings': {c: m[0]['settings'] for c, m in groups.items()},
        'anatomy': anatomy_rows(groups), 'calibration': calibration_rows(groups),
        'looks': look_rows(groups)}
    data['oracle_gap'] = oracle_gaps(banks, data['aggregates'])
    success = {c: stats.score_matrix([t['final'][HELDOUT]['summary']['success_rate']
                                      for t in m if HELDOUT in t['final']])
               for c, m in groups.items() if any(HELDOUT in t['final'] for t in m)}
    if len(success) > 1:
        data['improvement'] = stats.probability_of_improvement(success)
        no_collision = {c: stats.score_matrix(
            [1.0 - t['final'][HELDOUT]['summary']['collision_rate'] for t in m
             if HELDOUT in t['final']]) for c in success for m in [groups[c]]}
        data['improvement_collisions'] = stats.probability_of_improvement(no_collision)
    return data, success, curve_scores(groups)
