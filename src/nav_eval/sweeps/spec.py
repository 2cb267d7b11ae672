"""What a sweep runs, and the names of its files: the one definition of both (no Ray, no ROS).

A sweep directory holds ``sweep.json`` (the :class:`SweepSpec`), ``configs/<config>.yaml`` (one
training config per grid point), ``trials/[<config>_]seed<n>/`` (one run directory per trial,
exactly as ``nav-gym-train`` writes it, with its ``eval/``), ``baselines/<config>.json`` (random
policy and servo on both banks), ``logs/<trial>.log`` (every command a trial ran and its output),
``tune/`` (Ray Tune's experiment state), ``failed.json`` (trials that failed twice) and the
aggregate: ``Sweep.md``, ``Sweep.html``, ``results.json`` and ``figures/``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import re
import uuid
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from nav_eval.errors import EvaluationError, SweepError
from nav_eval.seeds import CURVE, HELDOUT_BANK, TRAIN_BANK, check_episodes, parse_seeds
from nav_gym.errors import NavGymError
from nav_gym.training.config import FIELDS, build
from nav_sim.core.world import load_arena
from nav_sim.errors import NavSimError
from nav_sim.paths import NAME_CHARACTERS, plain_name_problem
from nav_sim.ros.process import typed_params

SWEEP_FILE = 'sweep.json'
FAILED_FILE = 'failed.json'  # trials that failed twice, with their error and log tail
CONFIGS = 'configs'
TRIALS = 'trials'
BASELINES = 'baselines'
LOGS = 'logs'
TUNE = 'tune'
#: the aggregate, written by :mod:`nav_eval.sweeps.report`
SWEEP_REPORT = 'Sweep.md'
SWEEP_HTML = 'Sweep.html'
SWEEP_RESULTS = 'results.json'
SWEEP_FIGURES = 'figures'
#: what a sweep's summary keeps (``visnav-sweep --export``; what docs/sweeps commits)
SUMMARY_FILES = (SWEEP_REPORT, SWEEP_RESULTS, SWEEP_FILE, SWEEP_FIGURES, CONFIGS)
#: how configurations and trials are named (saved in sweep.json; a sweep.json without it is
#: version 1): 1: a sweep without a grid has the configuration ``defaults`` whatever its --set
#: settings, and trial names carry the configuration unless it is ``defaults``; 2: a sweep
#: without a grid names its configuration by its --set settings, and trial names carry the
#: configuration only when there are several
NAMING = 2
MAX_NAME = 120  # a configuration name is a file name (configs/<name>.yaml): keep it short
DEFAULTS = 'defaults'  # the configuration without a setting of its own
#: what joins the settings (``key=value``) in a configuration's name ...
SETTINGS_JOIN = '_'
#: ... and in the label of a folder of runs (``visnav-sweep --aggregate``), which is no file name
LABEL_JOIN = ', '


@dataclass
class SweepSpec:
    """Everything a sweep runs, saved as ``sweep.json`` (``--resume`` reads it back)."""

    sweep_dir: str
    seeds: list[int]
    grid: dict[str, list[str]] = field(default_factory=dict)
    fixed: dict[str, str] = field(default_factory=dict)
    train_seeds: list[int] = field(default_factory=lambda: list(TRAIN_BANK))
    heldout_seeds: list[int] = field(default_factory=lambda: list(HELDOUT_BANK))
    curve_seeds: list[int] = field(default_factory=lambda: list(CURVE))
    baselines: bool = True
    record: bool = False
    cpus_per_trial: float = 2
    gpus_per_trial: float = 0
    naming: int = 1  # NAMING of the code that created the sweep (older sweeps: 1)
    summary: str = ''  # --summary: a folder the sweep keeps its summary form in ('' = none)
    sweep_id: str = ''  # tells this sweep's summary from another's ('' = a sweep from before)

    def configurations(self) -> list[tuple[str, dict[str, str]]]:
        """Return (config name, overrides) for every grid point, in grid order.

        A grid point is named by its grid values; a sweep without a grid has one configuration,
        named by its ``--set`` settings (``defaults`` without any; see ``NAMING``).
        """
        keys = list(self.grid)
        out = []
        for values in itertools.product(*(self.grid[k] for k in keys)):
            point = dict(zip(keys, values, strict=True))
            named = point or (self.fixed if self.naming >= 2 else {})
            name = slug(SETTINGS_JOIN.join(f'{k}={v}' for k, v in named.items()))[:MAX_NAME]
            out.append((name if named else DEFAULTS, {**self.fixed, **point}))
        names = [name for name, _ in out]
        for name in names:
            if names.count(name) > 1:  # they would share one config file and trial folders
                raise SweepError(f'two grid points are both named {name!r} (a repeated value, '
                                 'values alike once made path-safe, or names alike in their '
                                 f"first {MAX_NAME} characters): make the grid's values differ")
        return out

    def trials(self) -> list[dict[str, Any]]:
        """Return every trial as the JSON-ready dict its Tune trainable receives."""
        root = Path(self.sweep_dir)
        common = {'cpus': int(max(1, self.cpus_per_trial)), 'gpus': self.gpus_per_trial,
                  'train_seeds': self.train_seeds, 'heldout_seeds': self.heldout_seeds}
        out = []
        configurations = self.configurations()
        for config_name, _ in configurations:
            config_file = str(root / CONFIGS / f'{config_name}.yaml')
            alone = len(configurations) == 1 if self.naming >= 2 else config_name == DEFAULTS
            prefix = '' if alone else f'{config_name}_'
            for seed in self.seeds:
                name = f'{prefix}seed{seed}'
                out.append({**common, 'kind': 'train', 'name': name, 'config': config_name,
                            'seed': seed, 'config_file': config_file,
                            'run_dir': str(root / TRIALS / name),
                            'log': str(root / LOGS / f'{name}.log'),
                            'curve_seeds': self.curve_seeds, 'record': self.record})
            if self.baselines:
                name = f'{prefix}baselines'
                out.append({**common, 'kind': 'baseline', 'name': name, 'config': config_name,
                            'config_file': config_file,
                            'out': str(root / BASELINES / f'{config_name}.json'),
                            'log': str(root / LOGS / f'{name}.log')})
        return out


def slug(text: str) -> str:
    """Make a directory-safe name of a plain name's characters (``nav_sim.paths``)."""
    return re.sub(f'[^{NAME_CHARACTERS}]+', '-', text).strip('-.') or 'config'


def parse_assignments(items: list[str], multi: bool) -> dict[str, Any]:
    """Parse ``KEY=V`` (or ``KEY=V1,V2`` when ``multi``) into a mapping, checking the names."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition('=')
        key = key.strip().replace('-', '_')
        if not sep or not key or value.strip() == '':
            raise SweepError(f"bad setting {item!r}: use KEY=VALUE{',VALUE' if multi else ''}")
        values = [v.strip() for v in value.split(',')] if multi else value.strip()
        if multi and any(v == '' for v in values):
            raise SweepError(f'bad grid {item!r}: an empty value')
        if key == 'sim_params':
            raise SweepError('give sim parameters by name, e.g. --set camera_hfov_deg=60 or '
                             '--grid num_obstacles=2,3')
        if key not in FIELDS and not _is_sim_param(key):
            raise SweepError(f'unknown setting {key!r}: use a training setting '
                             f'(nav-gym-train --help) or a sim parameter (config/sim.yaml)')
        out[key] = values
    return out


def _is_sim_param(key: str) -> bool:
    try:
        typed_params({key: 0})
    except NavSimError as exc:
        return 'unknown' not in str(exc)
    return True


def training_config(overrides: dict[str, str]) -> Any:
    """Build the full TrainConfig of one grid point (sim settings go into ``sim_params``).

    Its world is loaded and checked against the contract (docs/worlds.md): a bad world stops
    the sweep here, before any trial starts.  The world's settings are the defaults of the
    settings the grid point leaves out.
    """
    train = {k: v for k, v in overrides.items() if k in FIELDS and k != 'sim_params'}
    sim = {k: v for k, v in overrides.items() if k not in FIELDS}
    try:
        sim = typed_params(sim)
        config = build(None, {**train, 'sim_params': sim}).with_full_sim_params()
        load_arena(config.sim_params)
        return config
    except (NavGymError, NavSimError) as exc:
        lines = str(exc).splitlines() or ['']
        raise SweepError('\n'.join([f'configuration {overrides}: {lines[0]}', *lines[1:]])
                         ) from None


def write_configs(spec: SweepSpec) -> None:
    """Validate every grid point, then write its training config under ``configs/``.

    A bad grid point (a setting, a world) raises SweepError before anything is written.
    """
    configs = {name: dataclasses.replace(training_config(overrides), run_name='',
                                         runs_dir='runs')
               for name, overrides in spec.configurations()}
    folder = Path(spec.sweep_dir) / CONFIGS
    folder.mkdir(parents=True, exist_ok=True)
    for name, config in configs.items():
        (folder / f'{name}.yaml').write_text(config.to_yaml())


def load_spec(sweep_dir: Path) -> SweepSpec:
    """Read ``sweep.json`` of an existing sweep, or raise SweepError saying what to do."""
    path = sweep_dir / SWEEP_FILE
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SweepError(f'{sweep_dir} is not a sweep directory ({path}: {exc}); start one '
                         'with `visnav-sweep`') from None
    data['sweep_dir'] = str(sweep_dir.resolve())
    return SweepSpec(**data)


def summary_folder(path: Path | None, spec: SweepSpec) -> str:
    """Return ``--summary``'s folder as sweep.json keeps it ('' for none), or raise SweepError.

    The sweep replaces the folder after each finished trial, so it must lie outside the sweep's
    directory and be new, empty or this sweep's own summary (:func:`check_summary`).
    """
    if path is None:
        return ''
    destination, home = path.resolve(), Path(spec.sweep_dir).resolve()
    if destination == home or home in destination.parents or destination in home.parents:
        raise SweepError(f'--summary {path} overlaps the sweep directory {home}: name a folder '
                         'outside it')
    check_summary(destination, spec.sweep_id)
    return str(destination)


def summary_swap(destination: Path) -> tuple[Path, Path]:
    """Return the folders a summary is swapped through: the new one and the one it replaces."""
    name = destination.name
    return destination.with_name(f'.{name}.new'), destination.with_name(f'.{name}.old')


def check_summary(destination: Path, sweep_id: str) -> None:
    """Raise SweepError unless ``destination`` is new, empty or the summary of sweep ``sweep_id``.

    A swap that a stop cut between its two renames left ``destination`` missing and the
    summary it was replacing beside it: that one is put back first.
    """
    _, old = summary_swap(destination)
    if not destination.exists() and old.is_dir():
        old.rename(destination)
    if not destination.exists() or (destination.is_dir() and not any(destination.iterdir())):
        return
    kept = read_json(destination / SWEEP_FILE)
    if not (sweep_id and isinstance(kept, dict) and kept.get('sweep_id') == sweep_id):
        raise SweepError(f"--summary {destination} exists and is not this sweep's summary: name "
                         'a new folder (the sweep replaces it after each finished trial)')


def new_sweep_id() -> str:
    """Return a new sweep's identity, kept in its sweep.json and so in its summary's."""
    return uuid.uuid4().hex


def read_json(path: Path) -> Any:
    """Return a JSON file's contents, or None when it is missing or unreadable."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def save_spec(spec: SweepSpec) -> None:
    """Write ``sweep.json`` (all but the sweep's own directory, which is where it lies)."""
    data = dataclasses.asdict(spec)
    data.pop('sweep_dir')
    (Path(spec.sweep_dir) / SWEEP_FILE).write_text(json.dumps(data, indent=1) + '\n')


def trial_cpus(fixed: dict[str, str], grid: dict[str, list[str]]) -> float:
    """Return the CPUs a trial gets unless ``--cpus-per-trial`` says.

    SweepSpec's default (2), or one per sim and one for the learner, ``n_envs + 1``, for the
    largest ``n_envs`` that ``--set`` or ``--grid`` gives.  A value that is not a number is left
    to the settings' own check, which names it.
    """
    values = [fixed['n_envs']] if 'n_envs' in fixed else grid.get('n_envs', [])
    try:
        most = max((int(float(value)) for value in values), default=1)
    except ValueError:
        most = 1
    return float(max(SweepSpec.cpus_per_trial, most + 1))


def spec_from_args(args: argparse.Namespace) -> SweepSpec:
    """Build the spec of a new sweep from the command line and create its directory."""
    fixed = parse_assignments(args.set or [], multi=False)
    if args.total_timesteps is not None:
        fixed['total_timesteps'] = str(args.total_timesteps)
    grid = parse_assignments(args.grid or [], multi=True)
    both = sorted(set(fixed) & set(grid))
    if both:
        raise SweepError(f'{both} given both with --set and --grid: use one')
    if 'seed' in fixed or 'seed' in grid:
        raise SweepError('the training seed is the sweep axis: use --seeds, not seed=')
    name = args.name or datetime.now().strftime('sweep_%Y%m%d_%H%M%S')
    problem = plain_name_problem('--name', name)
    if problem:
        raise SweepError(problem)
    sweep_dir = (Path(args.storage) / name).resolve()
    if (sweep_dir / SWEEP_FILE).exists():
        raise SweepError(f'{sweep_dir} already holds a sweep: continue it with --resume '
                         f'{sweep_dir}, or choose another --name')
    try:
        seeds = {k: list(parse_seeds(getattr(args, k))) for k in
                 ('seeds', 'train_seeds', 'heldout_seeds')}
        curve = list(parse_seeds(args.curve_seeds)) if args.curve_seeds else []
        seed_bounds = FIELDS['seed'].metadata['bounds']
        for seed in seeds['seeds']:
            if not seed_bounds.allows(seed):
                raise SweepError(f'training seed must be {seed_bounds.describe()}, got {seed}')
        # a trial's final evaluation: its training and held-out seeds
        check_episodes(len(seeds['train_seeds']) + len(seeds['heldout_seeds']),
                       args.many_episodes)
    except EvaluationError as exc:
        raise SweepError(str(exc)) from None
    cpus = args.cpus_per_trial if args.cpus_per_trial is not None else trial_cpus(fixed, grid)
    if cpus < 1 or args.gpus_per_trial < 0:
        raise SweepError('--cpus-per-trial must be >= 1 and --gpus-per-trial >= 0')
    spec = SweepSpec(str(sweep_dir), seeds['seeds'], grid, fixed, seeds['train_seeds'],
                     seeds['heldout_seeds'], curve, not args.no_baselines, args.record,
                     cpus, args.gpus_per_trial, NAMING, sweep_id=new_sweep_id())
    for trial in spec.trials():  # each becomes a run name (long --set values can exceed it)
        problem = plain_name_problem('a trial name', trial['name'])
        if problem:
            raise SweepError(f'{problem}: shorten the --set or --grid values')
    spec.summary = summary_folder(args.summary, spec)
    write_configs(spec)  # creates the sweep directory once every grid point is valid
    save_spec(spec)
    return spec
