"""Write a sweep's aggregate: ``Sweep.md``, ``Sweep.html``, ``results.json`` and figures.

Reads only files (no ROS, no Ray): each trial is a run directory as ``nav-gym-train`` writes it
with its ``eval/results.json`` (final model on the training and held-out seeds) and
``eval/curve/<steps>/results.json`` (held-out success per checkpoint) and, where they were
kept, the episodes' traces (the failure anatomy, :mod:`nav_eval.analysis.anatomy`, and the value
calibration, :mod:`nav_eval.analysis.calibration`; with drawn looks, the outcomes by look,
:mod:`nav_eval.analysis.looks`); baselines are
``baselines/<config>.json``.  Trials with the same training settings (all but the seed and
bookkeeping such as the run name) form one configuration.  The same trials aggregated twice give
identical files (fixed bootstrap seed, PNGs without a software/date stamp).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from nav_eval.analysis import calibration, stats
from nav_eval.reporting.format import num, pct, table, to_html
from nav_eval.sweeps.collect import RATES, UNNAMED, jsonable
from nav_eval.sweeps.figures import write_figures
from nav_eval.sweeps.spec import (
    SWEEP_FIGURES,
    SWEEP_HTML,
    SWEEP_REPORT,
    SWEEP_RESULTS,
)
from nav_eval.sweeps.statistics import summarise
from nav_gym.training.spec import learner_of
from nav_sim.core.config import HELDOUT, TRAIN

FIGURES = (('intervals', 'Interval estimates per configuration: success'),
           ('intervals_collision', 'Interval estimates per configuration: collisions'),
           ('profile', 'Performance profile of held-out success'),
           ('curve', 'Sample efficiency'), ('improvement', 'Probability of improvement'))
ANATOMY = 'Failure anatomy (held-out)'
LOOKS = 'Outcomes by look (held-out)'
CALIBRATION = 'Value calibration (held-out)'
#: every section heading of Sweep.md (probability of improvement only with > 1 configuration)
SECTIONS = ('Configurations: held-out success and collisions', *(c for _, c in FIGURES),
            'Per seed', ANATOMY, LOOKS, CALIBRATION, 'Bank difficulty')


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
    lines += _configurations_markdown(data, figures)
    lines += _per_seed_markdown(data['per_seed'])
    lines += _anatomy_markdown(data['anatomy'])
    lines += _looks_markdown(data['looks'])
    lines += _calibration_markdown(data['calibration'])
    lines += _banks_markdown(data)
    if data['failed']:
        lines += ['## Failed trials', '']
        for name, error in sorted(data['failed'].items()):
            lines += [f'- **{name}** failed twice (Tune retried it once):', '', '```text',
                      *error.splitlines(), '```', '']
    if data['missing']:
        lines += ['## Missing', ''] + [f'- {m}' for m in data['missing']] + ['']
    return '\n'.join(lines)


def _configurations_markdown(data: dict[str, Any], figures: dict[str, str]) -> list[str]:
    lines = [f'## {SECTIONS[0]}', '']
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
    lines += ['Learners:', ''] + [
        f'- `{config}`: ' + ('unknown (its summary saved no settings)' if UNNAMED in settings
                             else learner_of(settings).describe())
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
    return lines


def _per_seed_markdown(per_seed: list[dict[str, Any]]) -> list[str]:
    head = ['Configuration', 'Trial', 'Seed', 'Steps']
    for split in (TRAIN, HELDOUT):
        head += [f'{split} success', f'{split} collision', f'{split} timeout', f'{split} SPL']
    rows = []
    for r in per_seed:
        row = [r['config'], r['trial'], r['seed'], r['steps']]
        for split in (TRAIN, HELDOUT):
            row += [pct(r.get(f'{split}_{k}')) for k in RATES[:3]]
            row += ['–' if r.get(f'{split}_mean_spl') is None else f"{r[f'{split}_mean_spl']:.3f}"]
        rows.append(row)
    return ['## Per seed', '', *table(head, rows)]


def _banks_markdown(data: dict[str, Any]) -> list[str]:
    lines = ['## Bank difficulty', '',
             'Success on the training bank and the held-out bank, each with its CI over '
             'scenarios: the random policy, the image-only servo (`nav_eval.evaluation.policies.'
             'ServoPolicy`), the privileged oracle (`OraclePolicy`: a plan on the true map '
             'driven with the same three actions, the decision period and the step limit; the '
             'share of scenarios the actions can solve at all) and the trained models.', '']
    rows = [[r['config'], r['policy'], f"{r['episodes']['train']} + {r['episodes']['heldout']}",
             _ci(r[TRAIN]), _ci(r[HELDOUT])] for r in data['banks']]
    lines += table(['Configuration', 'Policy', 'Episodes', 'Training bank', 'Held-out bank'],
                   rows)
    lines += [f"Verdict: {data['bank_verdict']}.", '']
    for config, gap in data.get('oracle_gap', {}).items():
        lines += [f"Gap to the oracle, `{config}`: held-out success IQM {pct(gap['iqm'])} "
                  f"against the oracle's {pct(gap['oracle'])}: {100 * gap['gap']:.0f} points.",
                  '']
    return lines


def _anatomy_markdown(rows: list[dict[str, Any]]) -> list[str]:
    lines = [f'## {ANATOMY}', '']
    if not rows:
        return lines + ['No held-out traces were kept (`eval/traces/dqn_heldout/seed_N.json`; a '
                        'trace without `goal_in_view` also needs its `seed_N_frames.npz`).', '']
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


def _looks_markdown(rows: list[dict[str, Any]]) -> list[str]:
    lines = [f'## {LOOKS}', '']
    if not rows:
        return lines + ['No held-out trace carried a drawn look (the sim parameter '
                        '`randomize_look`).', '']
    lines += ["The held-out episodes' outcomes by a factor of their scenario's drawn look, the "
              "configuration's seeds pooled (a comparison's summaries included, where they kept "
              "them): the obstacles' hue band (held-out looks draw from the odd bands, training "
              "looks from the even ones) and their luminance (Rec. 709 weights on the material "
              'colour; `nav_eval.analysis.looks`). A factor that fails in one bin and not the '
              'others points to what the policy has not learnt to see; the bins are few '
              "scenarios each, so read them as a hypothesis for a sweep, not as a result.", '']
    body = [[r['config'], r['seed'], r['factor'], r['bin'], r['episodes'],
             pct(r['success_rate']), pct(r['collision_rate']), pct(r['timeout_rate'])]
            for r in rows]
    lines += table(['Configuration', 'Seeds', 'Factor', 'Bin', 'Episodes', 'Success',
                    'Collisions', 'Time-outs'], body)
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


def write_sweep_report(folder: Path) -> Path:
    """Aggregate the trials under ``folder``; write the report files; return Sweep.md.

    Collecting (:mod:`nav_eval.sweeps.collect`) and the statistics
    (:mod:`nav_eval.sweeps.statistics`) come first; this module only writes: the figures,
    Sweep.md, Sweep.html and results.json.
    """
    data, success, curves = summarise(folder)
    figures = write_figures(folder / SWEEP_FIGURES, data, success, curves)
    data['sample_efficiency'] = {c: {'steps': v['steps'], 'seeds': v['seeds'],
                                     'iqm': v['iqm'], 'low': v['low'], 'high': v['high']}
                                 for c, v in curves.items() if 'iqm' in v}
    text = _markdown(folder, data, {k: f'{SWEEP_FIGURES}/{v}' for k, v in figures.items()})
    (folder / SWEEP_REPORT).write_text(text + '\n')
    (folder / SWEEP_HTML).write_text(to_html(text, folder, f'sweep {folder.name}'))
    (folder / SWEEP_RESULTS).write_text(json.dumps(jsonable(data), indent=1,
                                                   sort_keys=True) + '\n')
    return folder / SWEEP_REPORT
