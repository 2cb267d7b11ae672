"""Aggregate a sweep's trials into ``Sweep.md``, ``Sweep.html``, ``results.json`` and figures.

Reads only files (no ROS, no Ray): each trial is a run directory as ``nav-gym-train`` writes it
with its ``eval/results.json`` (final model on the training and held-out seeds) and
``eval/curve/<steps>/results.json`` (held-out success per checkpoint) and, where they were
kept, the episodes' traces (the failure anatomy, :mod:`nav_eval.analysis.anatomy`, and the value
calibration, :mod:`nav_eval.analysis.calibration`); baselines are
``baselines/<config>.json``.  Trials with the same training settings (all but the seed and
bookkeeping such as the run name) form one configuration.  The same trials aggregated twice give
identical files (fixed bootstrap seed, PNGs without a software/date stamp).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.analysis import anatomy, calibration, stats
from nav_eval.errors import SweepError
from nav_eval.reporting.format import num, pct, table, to_html
from nav_eval.seeds import HELDOUT_BANK, TRAIN_BANK, seed_text
from nav_eval.sweeps.figures import write_figures
from nav_eval.sweeps.spec import (
    BASELINES,
    FAILED_FILE,
    SWEEP_FIGURES,
    SWEEP_FILE,
    SWEEP_HTML,
    SWEEP_REPORT,
    SWEEP_RESULTS,
    TRIALS,
    SweepSpec,
)
from nav_gym.errors import NavGymError
from nav_gym.run_dir import (
    CONFIG,
    CURVE,
    EVAL,
    FINAL_MODEL,
    RESULTS,
    RESUME_COMMAND,
    SUMMARY,
    load_config,
    read_traces,
)
from nav_gym.train_config import TrainConfig, learner_of
from nav_sim.config import SimConfig
from nav_sim.errors import NavSimError

FINAL_SETS = {'train': 'dqn_train', 'heldout': 'dqn_heldout'}
BOOKKEEPING = ('seed', 'run_name', 'runs_dir', 'device', 'namespace', 'sim', 'sim_timeout',
               'save_replay_buffer', 'keep_replay_buffer')
FIGURES = (('intervals', 'Interval estimates per configuration: success'),
           ('intervals_collision', 'Interval estimates per configuration: collisions'),
           ('profile', 'Performance profile of held-out success'),
           ('curve', 'Sample efficiency'), ('improvement', 'Probability of improvement'))
ANATOMY = 'Failure anatomy (held-out)'
CALIBRATION = 'Value calibration (held-out)'
#: every section heading of Sweep.md (probability of improvement only with > 1 configuration)
SECTIONS = ('Configurations: held-out success and collisions', *(c for _, c in FIGURES),
            'Per seed', ANATOMY, CALIBRATION, 'Bank difficulty')
RATES = ('success_rate', 'collision_rate', 'timeout_rate', 'mean_spl')


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def trial_dirs(folder: Path) -> list[Path]:
    """Return the run directories of a sweep (``trials/*``) or of a folder of runs."""
    root = folder / TRIALS if (folder / TRIALS).is_dir() else folder
    return sorted(p for p in root.iterdir() if (p / CONFIG).is_file()) \
        if root.is_dir() else []


def read_trial(run_dir: Path) -> dict[str, Any]:
    """Collect one trial's seed, settings, final evaluation and curve points."""
    config = load_config(run_dir)
    results = _read_json(run_dir / EVAL / RESULTS) or {}
    sets = {s['name']: s for s in results.get('sets', [])}
    final = {split: sets[name] for split, name in FINAL_SETS.items() if name in sets}
    curve, curve_values = {}, {}
    for path in sorted((run_dir / EVAL / CURVE).glob(f'*/{RESULTS}')):
        data = _read_json(path) or {}
        for s in data.get('sets', []):
            curve[int(path.parent.name)] = {'success_rate': s['summary']['success_rate'],
                                            'seeds': s['seeds']}
            curve_values[int(path.parent.name)] = calibration.set_values(
                path.parent, s['name'], config, s['seeds'])
    summary = _read_json(run_dir / SUMMARY) or {}
    heldout = final.get('heldout')
    traces = (list(read_traces(run_dir / EVAL, FINAL_SETS['heldout'], heldout['seeds']))
              if heldout else [])
    key = {k: v for k, v in vars(_spelled_out(config)).items() if k not in BOOKKEEPING}
    return {'name': run_dir.name, 'run_dir': run_dir, 'seed': config.seed, 'settings': key,
            'final': final, 'curve': curve,
            'anatomy': anatomy.traces_anatomy(traces, results.get('arena'), half_fov(config)),
            'values': calibration.traces_values(traces, config),
            'curve_values': curve_values,
            'finished': (run_dir / FINAL_MODEL).is_file(),
            'wall_clock_s': summary.get('wall_clock_total_s'),
            'steps': summary.get('num_timesteps')}


def half_fov(config: TrainConfig) -> float:
    """Return the camera's horizontal half field of view (rad) of a run's sim settings."""
    return math.radians(SimConfig.from_params(config.sim_params).camera_hfov_deg) / 2.0


def _spelled_out(config: TrainConfig) -> TrainConfig:
    """Return a run's config with every sim parameter named, as runs save it since the worlds.

    An older run names only the sim parameters set then; those added since ran at their
    default (the world's), so trials of either age group together and name no ``None``.
    Where the run's world cannot be read here, the config stays as saved.
    """
    try:
        return config.with_full_sim_params()
    except (NavGymError, NavSimError):
        return config


def group_trials(trials: list[dict[str, Any]], names: dict[str, str]) -> dict[str, list[dict]]:
    """Group trials by their settings.

    A group is named from ``names`` (trial -> config) or by the settings that differ between
    groups (or from the defaults).
    """
    groups: list[tuple[dict, list[dict]]] = []
    for trial in trials:
        for settings, members in groups:
            if settings == trial['settings']:
                members.append(trial)
                break
        else:
            groups.append((trial['settings'], [trial]))
    defaults = {k: v for k, v in vars(TrainConfig().with_full_sim_params()).items()
                if k not in BOOKKEEPING}
    out: dict[str, list[dict]] = {}
    for settings, members in groups:
        label = next((names[m['name']] for m in members if m['name'] in names), None)
        if label is None:
            others = [s for s, _ in groups if s is not settings] or [defaults]
            label = _difference_label(settings, others)
        out[label] = sorted(members, key=lambda m: m['seed'])
    return out


def _flat(settings: dict[str, Any]) -> dict[str, Any]:
    flat = {k: v for k, v in settings.items() if k != 'sim_params'}
    flat.update(settings.get('sim_params') or {})
    return flat


def _difference_label(settings: dict, others: list[dict]) -> str:
    mine = _flat(settings)
    keys = sorted({k for o in others for k, v in _flat(o).items() if mine.get(k) != v})
    return ', '.join(f'{k}={mine.get(k)}' for k in keys) or 'defaults'


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
            rows.append(row)
    return rows


def anatomy_rows(groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return the held-out failure anatomy per configuration and seed, then pooled ('all')."""
    rows = []
    for config, members in groups.items():
        pooled = [e for t in members for e in t['anatomy']]
        if not pooled:
            continue
        pools = [(t['seed'], t['anatomy']) for t in members if t['anatomy']]
        for seed, episodes in pools + ([('all', pooled)] if len(pools) > 1 else []):
            for outcome, figures in anatomy.summarise(episodes).items():
                rows.append({'config': config, 'seed': seed, 'outcome': outcome, **figures})
    return rows


def calibration_rows(groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return the held-out value calibration per configuration and seed, then pooled.

    The final model's rows have ``steps`` None: one per seed with traces, then (with more than
    one) their pool; then one pooled row per checkpoint of the sample-efficiency curve whose
    traces were kept.  A pool's ``seed`` is 'all' when every seed of the configuration is in
    it, else the seed or seeds that are.
    """
    def pool(found: list[tuple[int, list]], members: list[dict]) -> tuple[Any, list]:
        seeds = [seed for seed, _ in found]
        label = 'all' if len(seeds) == len(members) else \
            seeds[0] if len(seeds) == 1 else ', '.join(map(str, seeds))
        return label, [e for _, episodes in found for e in episodes]

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
        scores = {c: stats.score_matrix([t['final']['heldout']['summary'][metric]
                                         for t in m if 'heldout' in t['final']])
                  for c, m in groups.items() if any('heldout' in t['final'] for t in m)}
        if scores:
            out[metric] = stats.aggregate_estimates(scores, metric)
    return out


def curve_scores(groups: dict[str, list[dict]]) -> dict[str, Any]:
    """Return per configuration the checkpoints every trial evaluated and a score matrix."""
    out = {}
    for config, members in groups.items():
        common = sorted(set.intersection(*(set(t['curve']) for t in members))) if members \
            else []
        if not common:
            continue
        matrix = np.array([[[t['curve'][s]['success_rate'] for s in common]] for t in members])
        out[config] = {'steps': common, 'scores': matrix,
                       'seeds': members[0]['curve'][common[0]]['seeds']}
    return out


def bank_rows(folder: Path, groups: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Return success on both banks with CIs over scenarios: baselines and the DQN trials."""
    rows = []
    for config in groups:
        baseline = _read_json(folder / BASELINES / f'{config}.json') or {}
        by_policy: dict[str, dict[str, list]] = {}
        for s in baseline.get('sets', []):
            by_policy.setdefault(s['policy'], {})[s['split']] = s['episodes']
        dqn = {split: [e for t in groups[config] for e in t['final'].get(split, {})
                       .get('episodes', [])] for split in FINAL_SETS}
        if all(dqn.values()):
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
            oracle = row['heldout']['point']
            out[row['config']] = {'oracle': oracle, 'iqm': iqm['point'],
                                  'gap': oracle - iqm['point']}
    return out


def _ci(estimate: dict[str, float] | None, digits: int = 0) -> str:
    if not estimate:
        return '–'
    return (f"{pct(estimate['point'], digits)} [{pct(estimate['low'], digits)}, "
            f"{pct(estimate['high'], digits)}]")


def _markdown(folder: Path, data: dict[str, Any], figures: dict[str, str]) -> str:
    lines = [f'# Sweep: {folder.name}', '',
             f"{len(data['trials'])} trials in {len(data['configurations'])} configuration(s). "
             'Intervals are 95 % stratified-bootstrap CIs (rliable, percentile method, '
             f'{stats.REPS} resamples, random state {stats.RANDOM_STATE}) over the training '
             'seeds of a configuration; for the banks, over scenarios.', '']
    lines += [f'## {SECTIONS[0]}', '']
    rows = []
    for config in data['configurations']:
        evaluated = sum(1 for r in data['per_seed'] if r['config'] == config
                        and r.get('heldout_success_rate') is not None)  # not the unfinished
        for metric in ('success_rate', 'collision_rate'):
            est = data['aggregates'].get(metric, {}).get(config)
            if est:
                rows.append([config, metric.replace('_', ' '), evaluated]
                            + [_ci(est[a]) for a in stats.AGGREGATES])
    lines += table(['Configuration', 'Held-out', 'Seeds', *stats.AGGREGATES], rows)
    lines += ['The optimality gap of the collision rate is its gap to 0 collisions.', '']
    lines += ['Learners:', ''] + [f'- `{config}`: {learner_of(settings).describe()}'
                                  for config, settings in data['settings'].items()] + ['']
    for key, caption in FIGURES:
        if key in figures:
            lines += [f'## {caption}', '', f'![{caption}]({figures[key]})', '']
    if 'improvement' in data and data['improvement']:
        rows = [[k, _ci(v, 0)] for k, v in data['improvement'].items()]
        lines += table(['P(X > Y), held-out success', 'estimate [95 % CI]'], rows)
    if data.get('improvement_collisions'):
        rows = [[k, _ci(v, 0)] for k, v in data['improvement_collisions'].items()]
        lines += table(['P(X > Y), held-out episodes without a collision (1 - collision rate)',
                        'estimate [95 % CI]'], rows)
    lines += ['## Per seed', '']
    head = ['Configuration', 'Trial', 'Seed', 'Steps']
    for split in ('train', 'heldout'):
        head += [f'{split} success', f'{split} collision', f'{split} timeout', f'{split} SPL']
    rows = []
    for r in data['per_seed']:
        row = [r['config'], r['trial'], r['seed'], r['steps']]
        for split in ('train', 'heldout'):
            row += [pct(r.get(f'{split}_{k}')) for k in RATES[:3]]
            row += ['–' if r.get(f'{split}_mean_spl') is None else f"{r[f'{split}_mean_spl']:.3f}"]
        rows.append(row)
    lines += table(head, rows)
    lines += _anatomy_markdown(data['anatomy'])
    lines += _calibration_markdown(data['calibration'])
    lines += ['## Bank difficulty', '',
              'Success on the training bank and the held-out bank, each with its CI over '
              'scenarios: the random policy, the image-only servo (`nav_eval.evaluation.policies.'
              'ServoPolicy`), the privileged oracle (`OraclePolicy`: a plan on the true map '
              'driven with the same three actions, the decision period and the step limit; the '
              'share of scenarios the actions can solve at all) and the trained models.', '']
    rows = [[r['config'], r['policy'], f"{r['episodes']['train']} + {r['episodes']['heldout']}",
             _ci(r['train']), _ci(r['heldout'])] for r in data['banks']]
    lines += table(['Configuration', 'Policy', 'Episodes', 'Training bank', 'Held-out bank'],
                   rows)
    lines += [f"Verdict: {data['bank_verdict']}.", '']
    for config, gap in data.get('oracle_gap', {}).items():
        lines += [f"Gap to the oracle, `{config}`: held-out success IQM {pct(gap['iqm'])} "
                  f"against the oracle's {pct(gap['oracle'])}: {100 * gap['gap']:.0f} points.",
                  '']
    if data['failed']:
        lines += ['## Failed trials', '']
        for name, error in sorted(data['failed'].items()):
            lines += [f'- **{name}** failed twice (Tune retried it once):', '', '```text',
                      *error.splitlines(), '```', '']
    if data['missing']:
        lines += ['## Missing', ''] + [f'- {m}' for m in data['missing']] + ['']
    return '\n'.join(lines)


def _anatomy_markdown(rows: list[dict[str, Any]]) -> list[str]:
    lines = [f'## {ANATOMY}', '']
    if not rows:
        return lines + ['No held-out traces were kept (`eval/traces/dqn_heldout`).', '']
    lines += ['How the held-out episodes spent their decisions, by outcome: *finding* the goal '
              '(decisions before it was first in view; episodes that never saw it) and '
              '*reaching* it (the share of decisions taken with the goal in view, how many of '
              'those drove forward, left/right reversals per 100 decisions). A time-out that '
              'saw the goal late failed to search; one that saw it most of the time and '
              'reversed failed to approach. *Hits out of view*: of the collisions, how many '
              "touched a wall or an obstacle outside the camera's horizontal field of view "
              '(from the final pose and the true map; `nav_eval.analysis.anatomy`).', '']

    def number(value: Any, digits: int = 0) -> str:
        return '–' if value is None else f'{value:.{digits}f}'

    body = [[r['config'], r['seed'], r['outcome'], r['episodes'],
             number(r['median_first_in_view'], 1), r['never_in_view'], pct(r['in_view_share']),
             pct(r['forward_in_view']), number(r['reversals_per_100']),
             number(r.get('hit_out_of_view'))] for r in rows]
    lines += table(['Configuration', 'Seed', 'Outcome', 'Episodes', 'Decisions before in view '
                    '(median)', 'Never in view', 'Goal in view', 'Forward when in view',
                    'Reversals / 100', 'Hits out of view'], body)
    return lines


def _calibration_markdown(rows: list[dict[str, Any]]) -> list[str]:
    lines = [f'## {CALIBRATION}', '']
    if not rows:
        return lines + ['No held-out episode was traced with its Q-values '
                        '(`eval/traces/dqn_heldout`).', '']
    lines += ['The value Q(s, a) of each action the model took against the discounted return '
              "that followed it (the run's gamma), over the held-out episodes that ended in a "
              "goal or a collision (a time-out's return after the limit is unknown). Q - return "
              '> 0 is overestimation; *near* is the final approach (decisions closer than '
              f'{calibration.NEAR_GOAL:g} m to the goal). *Above any return* needs no returns '
              'and takes every decision, time-outs included: the share whose Q is above the '
              'most any episode can return from there (the goal bonus plus the progress reward '
              'of the whole distance to the goal). Rows with a step count are the checkpoints '
              'of the sample-efficiency curve, seeds pooled '
              '(`nav_eval.analysis.calibration`).', '']

    def signed(value: Any) -> str:
        return '–' if value is None else f'{value:+.2f}'

    body = [[r['config'], r['seed'], 'final' if r['steps'] is None else r['steps'],
             r['episodes'], r['decisions'], num(r['q']), num(r['return']),
             signed(r['overestimate']), signed(r['near']), signed(r['far']),
             f"{pct(r['above_bound'])} of {r['all_decisions']}"] for r in rows]
    lines += table(['Configuration', 'Seed', 'Model', 'Ended episodes', 'Their decisions',
                    'Mean Q', 'Mean return', 'Q - return', 'Near the goal', 'Farther',
                    'Q above any return'], body)
    return lines


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return round(float(value), 6)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, Path):
        return value.name
    return value


def write_sweep_report(folder: Path) -> Path:
    """Aggregate the trials under ``folder``; write the report files; return Sweep.md."""
    runs = trial_dirs(folder)
    if not runs:
        raise SweepError(f'{folder} holds no run directories (trials/*/config.yaml): run a '
                         'sweep with `visnav-sweep` or pass a folder of training runs')
    spec = _read_json(folder / SWEEP_FILE) or {}
    names = _trial_configs(folder, spec)
    trials = [read_trial(r) for r in runs]
    groups = group_trials(trials, names)
    missing = [_missing_line(t, folder, spec) for t in trials if len(t['final']) < 2]
    banks = bank_rows(folder, groups)
    data: dict[str, Any] = {
        'configurations': {c: [t['name'] for t in m] for c, m in groups.items()},
        'trials': [t['name'] for t in trials], 'per_seed': per_seed_rows(groups),
        'aggregates': configuration_stats(groups), 'banks': banks,
        'bank_verdict': stats.bank_verdict([r for r in banks]), 'missing': missing,
        'failed': _read_json(folder / FAILED_FILE) or {},
        'settings': {c: m[0]['settings'] for c, m in groups.items()},
        'anatomy': anatomy_rows(groups), 'calibration': calibration_rows(groups)}
    data['oracle_gap'] = oracle_gaps(banks, data['aggregates'])
    curves = curve_scores(groups)
    success = {c: stats.score_matrix([t['final']['heldout']['summary']['success_rate']
                                      for t in m if 'heldout' in t['final']])
               for c, m in groups.items() if any('heldout' in t['final'] for t in m)}
    if len(success) > 1:
        data['improvement'] = stats.probability_of_improvement(success)
        no_collision = {c: stats.score_matrix(
            [1.0 - t['final']['heldout']['summary']['collision_rate'] for t in m
             if 'heldout' in t['final']]) for c in success for m in [groups[c]]}
        data['improvement_collisions'] = stats.probability_of_improvement(no_collision)
    figures = write_figures(folder / SWEEP_FIGURES, data, success, curves)
    data['sample_efficiency'] = {c: {'steps': v['steps'], 'seeds': v['seeds'],
                                     'iqm': v['iqm'], 'low': v['low'], 'high': v['high']}
                                 for c, v in curves.items() if 'iqm' in v}
    text = _markdown(folder, data, {k: f'{SWEEP_FIGURES}/{v}' for k, v in figures.items()})
    (folder / SWEEP_REPORT).write_text(text + '\n')
    (folder / SWEEP_HTML).write_text(to_html(text, folder, f'sweep {folder.name}'))
    (folder / SWEEP_RESULTS).write_text(json.dumps(_jsonable(data), indent=1,
                                                   sort_keys=True) + '\n')
    return folder / SWEEP_REPORT


def _missing_line(trial: dict[str, Any], folder: Path, spec: dict[str, Any]) -> str:
    """Say what a trial without its final evaluation lacks and the command that completes it.

    In a sweep (``spec`` from sweep.json) its resume does both; a folder of runs has the banks.
    """
    if spec:
        # a sweep's resume finishes its trainings and then their evaluations
        what = 'training unfinished' if not trial['finished'] else 'no final evaluation'
        return f"{trial['name']}: {what}; run `visnav-sweep --resume {folder}`"
    if not trial['finished']:
        return (f"{trial['name']}: training unfinished; run `{RESUME_COMMAND} {trial['run_dir']}`,"
                ' then evaluate it')
    return (f"{trial['name']}: no final evaluation; run `nav-eval-evaluate {trial['run_dir']} "
            f'--sets dqn_train,dqn_heldout --train-seeds {seed_text(TRAIN_BANK)} '
            f'--heldout-seeds {seed_text(HELDOUT_BANK)} --no-record`')


def _trial_configs(folder: Path, spec: dict[str, Any]) -> dict[str, str]:
    """Map trial names to configuration names from ``sweep.json`` (empty without one)."""
    if not spec:
        return {}
    try:
        trials = SweepSpec(**{**spec, 'sweep_dir': str(folder)}).trials()
    except TypeError:
        return {}
    return {t['name']: t['config'] for t in trials if t['kind'] == 'train'}
