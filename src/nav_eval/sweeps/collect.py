"""A sweep's trials, read from their files and grouped into configurations (no ROS, no Ray)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.analysis import anatomy, calibration, looks
from nav_eval.errors import SweepError
from nav_eval.seeds import HELDOUT_BANK, TRAIN_BANK, seed_text
from nav_eval.sweeps.spec import (
    DEFAULTS,
    LABEL_JOIN,
    SWEEP_RESULTS,
    TRIALS,
    SweepSpec,
    read_json,
)
from nav_gym.errors import NavGymError
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import (
    CONFIG,
    CURVE,
    EVAL,
    FINAL_MODEL,
    RESULTS,
    RESUME_COMMAND,
    SUMMARY,
    is_curve_point,
    load_config,
    read_traces,
    run_settings,
)
from nav_sim.core.config import HELDOUT, TRAIN, SimConfig
from nav_sim.errors import NavSimError

FINAL_SETS = {TRAIN: 'dqn_train', HELDOUT: 'dqn_heldout'}
#: a final evaluation's rates, per split (the per-seed rows of results.json)
RATES = ('success_rate', 'collision_rate', 'timeout_rate', 'mean_spl')
#: the settings of a summary's configuration that was saved without its settings: only its name
UNNAMED = 'summary configuration'


#: the settings a training config has today
TRAIN_FIELDS = frozenset(f.name for f in dataclasses.fields(TrainConfig))
#: settings that say how a run is kept and where it runs, not what it learns: trials that differ
#: only in these are one configuration (a checkpoint's save changes nothing the learner draws)
BOOKKEEPING = ('seed', 'run_name', 'runs_dir', 'device', 'namespace', 'sim', 'sim_timeout',
               'save_replay_buffer', 'keep_replay_buffer', 'checkpoint_freq')


def trial_dirs(folder: Path) -> list[Path]:
    """Return the run directories of a sweep (``trials/*``) or of a folder of runs."""
    root = folder / TRIALS if (folder / TRIALS).is_dir() else folder
    return sorted(p for p in root.iterdir() if (p / CONFIG).is_file()) \
        if root.is_dir() else []


def exported_dirs(folder: Path) -> list[Path]:
    """Return the sweep summaries (``visnav-sweep --export``) directly in ``folder``.

    A summary is a folder with a results.json that has per-seed rows, and no run directory.  A
    whole sweep directory there is left out, with a line that says how to include it: its
    trials' own folders have more than its summary (episodes, curves, anatomy).
    """
    if not folder.is_dir():
        return []
    out = []
    for path in sorted(p for p in folder.iterdir() if p.is_dir() and not (p / CONFIG).is_file()):
        if 'per_seed' not in (read_json(path / SWEEP_RESULTS) or {}):
            continue
        if (path / TRIALS).is_dir():
            print(f'{path.name}: a sweep directory, left out: link its trials ({path / TRIALS}/*) '
                  f'into {folder}, or aggregate its --export', flush=True)
            continue
        out.append(path)
    return out


def read_exported(summaries: list[Path]) -> list[dict[str, Any]]:
    """Return the trials of sweep summaries, from their per-seed rows, each trial once.

    A summary keeps each trial's final rates and its curve's success rates, not its episodes:
    such a trial (``exported``) counts in the aggregates, the probability of improvement and the
    curve, and the held-out outcomes by look where its summary kept them, and it has no
    anatomy, calibration or pooled bank row.  Its settings are read as an
    older run's config is (:func:`_summary_settings`).  Its name is ``<summary>:<trial>``.  A
    trial that two summaries hold (a comparison's summary beside the sweep's own) counts once:
    the first read, with the curve and the counts by look of a later copy where the first kept
    none.
    """
    trials, seen = [], {}
    for summary in summaries:
        data = read_json(summary / SWEEP_RESULTS) or {}
        for row in data.get('per_seed', []):
            settings = _summary_settings(data.get('settings', {}), row, summary.name)
            # the trial's own figures, not its name (comparisons rename their trials), at a
            # precision that every writer of results.json kept
            figures = [row.get(k) for k in ('steps', 'wall_clock_s', *(
                f'{split}_{rate}' for split in FINAL_SETS for rate in (*RATES, 'episodes')))]
            key = json.dumps([row['seed'], jsonable(settings),
                              [f'{v:.4g}' if isinstance(v, float) else v for v in figures]])
            if key in seen:
                seen[key]['curve'] = seen[key]['curve'] or _summary_curve(row)
                seen[key]['looks'] = seen[key]['looks'] or row.get('looks', {})
                continue
            final = {split: {'summary': {**{rate: row[f'{split}_{rate}'] for rate in RATES},
                                         'episodes': row[f'{split}_episodes']}}
                     for split in FINAL_SETS if f'{split}_success_rate' in row}
            seen[key] = {'name': f"{summary.name}:{row['trial']}", 'run_dir': summary,
                         'seed': row['seed'], 'settings': settings,
                         'final': final, 'curve': _summary_curve(row), 'anatomy': [],
                         'looks': row.get('looks', {}),
                         'values': [], 'curve_values': {}, 'finished': True, 'exported': True,
                         'wall_clock_s': row.get('wall_clock_s'), 'steps': row.get('steps')}
            trials.append(seen[key])
    return trials


def _summary_curve(row: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """Return a summary trial's curve points as :func:`read_trial` gives a run's.

    Older summaries kept none.
    """
    return {int(steps): {'success_rate': rate, 'seeds': row['curve_seeds']}
            for steps, rate in row.get('curve', {}).items()}


def _summary_settings(settings: dict[str, Any], row: dict[str, Any], summary: str
                      ) -> dict[str, Any]:
    """Return a summary trial's settings as :func:`read_trial` gives a run's.

    The settings its code did not have yet take the values of that time, as an older run's
    config.yaml does (``run_settings``: today's defaults, except where a default changed), and
    its world fills the sim parameters.  A setting that today's code no longer has is kept, so
    the trial groups only with its like.  A row whose configuration has no settings in the
    summary is a group of its own (named by its configuration).
    """
    kept = settings.get(row['config'])
    if kept is None:
        return {UNNAMED: row['config']}
    kept = {k: v for k, v in kept.items() if k not in BOOKKEEPING}
    known = {k: v for k, v in kept.items() if k in TRAIN_FIELDS}
    try:
        config = _spelled_out(TrainConfig(**run_settings(known)))
    except (NavGymError, NavSimError, TypeError, ValueError) as exc:
        print(f"{summary}: the settings of {row['config']} do not load here ({exc}); its "
              'trials are grouped by the settings as saved', flush=True)
        return run_settings(kept)
    return {**_settings(config), **{k: v for k, v in kept.items() if k not in known}}


def jsonable(value: Any) -> Any:
    """Return ``value`` as results.json writes it: lists, plain numbers, 6 significant digits."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(f'{float(value):.6g}')
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, Path):
        return value.name
    return value


def _settings(config: TrainConfig) -> dict[str, Any]:
    """Return a config's settings as a trial holds them: all but the bookkeeping."""
    return {k: v for k, v in vars(config).items() if k not in BOOKKEEPING}


def read_trial(run_dir: Path) -> dict[str, Any]:
    """Collect one trial's seed, settings, final evaluation and curve points."""
    config = load_config(run_dir)
    results = read_json(run_dir / EVAL / RESULTS) or {}
    sets = {s['name']: s for s in results.get('sets', [])}
    final = {split: sets[name] for split, name in FINAL_SETS.items() if name in sets}
    curve, curve_values = {}, {}
    for path in sorted((run_dir / EVAL / CURVE).glob(f'*/{RESULTS}')):
        name = path.parent.name
        if not (name.isdigit() and is_curve_point(steps := int(name), config)):
            continue  # a stop's checkpoint, evaluated by an older sweep: not a curve point
        data = read_json(path) or {}
        for s in data.get('sets', []):
            curve[steps] = {'success_rate': s['summary']['success_rate'], 'seeds': s['seeds']}
            curve_values[steps] = calibration.set_values(
                path.parent, s['name'], config, s['seeds'])
    summary = read_json(run_dir / SUMMARY) or {}
    heldout = final.get(HELDOUT)
    traces = (list(read_traces(run_dir / EVAL, FINAL_SETS[HELDOUT], heldout['seeds']))
              if heldout else [])
    key = _settings(_spelled_out(config))
    return {'name': run_dir.name, 'run_dir': run_dir, 'seed': config.seed, 'settings': key,
            'final': final, 'curve': curve,
            'anatomy': anatomy.traces_anatomy(traces, results.get('arena'), half_fov(config)),
            'values': calibration.traces_values(traces, config),
            'looks': looks.count_outcomes(traces),
            'curve_values': curve_values,
            'finished': (run_dir / FINAL_MODEL).is_file(), 'exported': False,
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
            if jsonable(settings) == jsonable(trial['settings']):
                members.append(trial)
                break
        else:
            groups.append((trial['settings'], [trial]))
    defaults = _settings(TrainConfig().with_full_sim_params())
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
    keys = sorted({k for o in others for k, v in _flat(o).items()
                   if jsonable(mine.get(k)) != jsonable(v)})
    return LABEL_JOIN.join(f'{k}={mine.get(k)}' for k in keys) or DEFAULTS


def missing_line(trial: dict[str, Any], folder: Path, spec: dict[str, Any]) -> str:
    """Say what a trial without its final evaluation lacks and the command that completes it.

    In a sweep (``spec`` from sweep.json) its resume does both; a folder of runs has the banks.
    A summary's trial is complete only where its own folder is (elsewhere).
    """
    if trial['exported']:
        return (f"{trial['name']}: no final evaluation in its summary ({trial['run_dir']}); "
                'complete the trial where its sweep directory is, then export it again')
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


def trial_configs(folder: Path, spec: dict[str, Any]) -> dict[str, str]:
    """Map trial names to configuration names from ``sweep.json`` (empty without one)."""
    if not spec:
        return {}
    try:
        trials = SweepSpec(**{**spec, 'sweep_dir': str(folder)}).trials()
    except (TypeError, SweepError):  # another version's spec, or one whose names clash
        return {}
    return {t['name']: t['config'] for t in trials if t['kind'] == 'train'}
