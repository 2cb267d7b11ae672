"""Train and evaluate several seeds of one or more configurations on Ray Tune, then aggregate.

    ros2 run nav_eval sweep [--seeds 1-5] [--grid KEY=V1,V2 ...] [--set KEY=V ...]
                            [--total-timesteps N] [--cpus-per-trial 2] [--gpus-per-trial 0]
                            [--address auto|HOST:PORT] [--storage DIR] [--name NAME]
    ros2 run nav_eval sweep --resume SWEEP_DIR      # continue an interrupted sweep
    ros2 run nav_eval sweep --aggregate DIR         # statistics of finished trials only

A sweep directory holds ``sweep.json`` (its settings), ``configs/<config>.yaml`` (one training
config per grid point), ``trials/[<config>_]seed<n>/`` (one run directory per trial, exactly as
``nav-gym-train`` writes it, with its ``eval/``), ``baselines/<config>.json`` (random policy and
servo on both banks), ``logs/<trial>.log`` (every command a trial ran and its output),
``tune/`` (Ray Tune's experiment state) and the aggregate: ``Sweep.md``, ``Sweep.html``,
``results.json`` and ``figures/``.  Ray Tune schedules the trials (one per seed and
configuration, plus one baseline trial per configuration), places them on the cluster's CPUs and
GPUs, retries a failed trial once and restores an interrupted sweep.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import re
import sys
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from nav_eval.errors import NavEvalError
from nav_eval.evaluate import parse_seeds
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.errors import NavGymError
from nav_gym.train_config import FIELDS, build
from nav_sim.errors import NavSimError
from nav_sim.sim_process import typed_params

SWEEP_FILE = 'sweep.json'
FAILED_FILE = 'failed.json'  # trials that failed twice, with their error and log tail
INTERRUPTED = 130
#: how configurations and trials are named (saved in sweep.json; a sweep.json without it is
#: version 1): 1: a sweep without a grid has the configuration ``defaults`` whatever its --set
#: settings, and trial names carry the configuration unless it is ``defaults``; 2: a sweep
#: without a grid names its configuration by its --set settings, and trial names carry the
#: configuration only when there are several
NAMING = 2
MAX_NAME = 120  # a configuration name is a file name (configs/<name>.yaml): keep it short


class SweepError(NavEvalError, ValueError):
    """A sweep's settings or directory are not usable (the message says what to change)."""


@dataclass
class SweepSpec:
    """Everything a sweep runs, saved as ``sweep.json`` (``--resume`` reads it back)."""

    sweep_dir: str
    seeds: list[int]
    grid: dict[str, list[str]] = field(default_factory=dict)
    fixed: dict[str, str] = field(default_factory=dict)
    train_seeds: list[int] = field(default_factory=lambda: list(range(101, 201)))
    heldout_seeds: list[int] = field(default_factory=lambda: list(range(201, 301)))
    curve_seeds: list[int] = field(default_factory=lambda: list(range(201, 231)))
    baselines: bool = True
    record: bool = False
    cpus_per_trial: float = 2
    gpus_per_trial: float = 0
    naming: int = 1  # NAMING of the code that created the sweep (older sweeps: 1)

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
            name = slug('_'.join(f'{k}={v}' for k, v in named.items()))[:MAX_NAME]
            out.append((name if named else 'defaults', {**self.fixed, **point}))
        return out

    def trials(self) -> list[dict[str, Any]]:
        """Return every trial as the JSON-ready dict its Tune trainable receives."""
        root = Path(self.sweep_dir)
        common = {'cpus': int(max(1, self.cpus_per_trial)), 'gpus': self.gpus_per_trial,
                  'train_seeds': self.train_seeds, 'heldout_seeds': self.heldout_seeds}
        out = []
        configurations = self.configurations()
        for config_name, _ in configurations:
            config_file = str(root / 'configs' / f'{config_name}.yaml')
            alone = len(configurations) == 1 if self.naming >= 2 else config_name == 'defaults'
            prefix = '' if alone else f'{config_name}_'
            for seed in self.seeds:
                name = f'{prefix}seed{seed}'
                out.append({**common, 'kind': 'train', 'name': name, 'config': config_name,
                            'seed': seed, 'config_file': config_file,
                            'run_dir': str(root / 'trials' / name),
                            'log': str(root / 'logs' / f'{name}.log'),
                            'curve_seeds': self.curve_seeds, 'record': self.record})
            if self.baselines:
                name = f'{prefix}baselines'
                out.append({**common, 'kind': 'baseline', 'name': name, 'config': config_name,
                            'config_file': config_file,
                            'out': str(root / 'baselines' / f'{config_name}.json'),
                            'log': str(root / 'logs' / f'{name}.log')})
        return out


def slug(text: str) -> str:
    """Make a directory-safe name (letters, digits, ``=._-``)."""
    return re.sub(r'[^A-Za-z0-9=._-]+', '-', text).strip('-') or 'config'


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
    """Build the full TrainConfig of one grid point (sim settings go into ``sim_params``)."""
    train = {k: v for k, v in overrides.items() if k in FIELDS and k != 'sim_params'}
    sim = {k: v for k, v in overrides.items() if k not in FIELDS}
    try:
        sim = typed_params(sim)
        return build(None, {**train, 'sim_params': sim}).with_full_sim_params()
    except (NavGymError, NavSimError) as exc:
        raise SweepError(f'configuration {overrides}: {exc}') from None


def write_configs(spec: SweepSpec) -> None:
    """Validate every grid point and write its training config under ``configs/``."""
    folder = Path(spec.sweep_dir) / 'configs'
    folder.mkdir(parents=True, exist_ok=True)
    for name, overrides in spec.configurations():
        config = dataclasses.replace(training_config(overrides), run_name='', runs_dir='runs')
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
    sweep_dir = (Path(args.storage) / name).resolve()
    if (sweep_dir / SWEEP_FILE).exists():
        raise SweepError(f'{sweep_dir} already holds a sweep: continue it with --resume '
                         f'{sweep_dir}, or choose another --name')
    try:
        seeds = {k: list(parse_seeds(getattr(args, k))) for k in
                 ('seeds', 'train_seeds', 'heldout_seeds')}
        curve = list(parse_seeds(args.curve_seeds)) if args.curve_seeds else []
    except NavEvalError as exc:
        raise SweepError(str(exc)) from None
    if args.cpus_per_trial < 1 or args.gpus_per_trial < 0:
        raise SweepError('--cpus-per-trial must be >= 1 and --gpus-per-trial >= 0')
    spec = SweepSpec(str(sweep_dir), seeds['seeds'], grid, fixed, seeds['train_seeds'],
                     seeds['heldout_seeds'], curve, not args.no_baselines, args.record,
                     args.cpus_per_trial, args.gpus_per_trial, NAMING)
    sweep_dir.mkdir(parents=True, exist_ok=True)
    write_configs(spec)
    data = dataclasses.asdict(spec)
    data.pop('sweep_dir')
    (sweep_dir / SWEEP_FILE).write_text(json.dumps(data, indent=1) + '\n')
    return spec


def run_sweep(spec: SweepSpec, address: str | None, resume: bool,
              retry_failed: bool = False) -> int:
    """Run (or continue) the sweep's trials on Ray Tune; aggregate; return an exit code."""
    from nav_eval.sweep_trial import trial_finished
    from nav_eval.sweep_tune import run_trials
    trials = spec.trials()
    print(f'sweep {spec.sweep_dir}: {len(trials)} trials ({len(spec.configurations())} '
          f'configuration(s) x {len(spec.seeds)} seed(s)'
          f"{' + baselines' if spec.baselines else ''}), {spec.cpus_per_trial:g} CPU"
          f"{f' + {spec.gpus_per_trial:g} GPU' if spec.gpus_per_trial else ''} per trial",
          flush=True)
    failures = Path(spec.sweep_dir) / FAILED_FILE
    done = {t['name'] for t in trials if trial_finished(t)}
    if resume and not retry_failed:  # failed for good in an earlier session: not run again
        done |= set(_read_failures(failures))
    outcome = run_trials(spec, trials, address, resume, retry_failed, done)
    if outcome.failed:
        failures.write_text(json.dumps(outcome.failed, indent=1, sort_keys=True) + '\n')
    else:
        failures.unlink(missing_ok=True)
    for name, error in sorted(outcome.failed.items()):
        print(f'trial {name} FAILED (tried {outcome.attempts.get(name, 2)} times): {error}',
              flush=True)
    if outcome.interrupted:
        print(f'sweep interrupted: {len(outcome.finished)} of {len(trials)} trials finished; '
              f'continue with: visnav-sweep --resume {spec.sweep_dir}', flush=True)
        return INTERRUPTED
    aggregate(Path(spec.sweep_dir))
    return 1 if outcome.failed else 0


def _read_failures(path: Path) -> dict[str, str]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def aggregate(folder: Path) -> Path:
    """Write Sweep.md, Sweep.html, results.json and figures/ of the finished trials."""
    from nav_eval.sweep_report import write_sweep_report
    path = write_sweep_report(folder)
    print(f'sweep report: {path} (+ Sweep.html, results.json)', flush=True)
    return path


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``visnav-sweep``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    what = parser.add_mutually_exclusive_group()
    what.add_argument('--resume', type=Path, metavar='SWEEP_DIR',
                      help='continue an interrupted sweep (finished trials are not re-run)')
    what.add_argument('--aggregate', type=Path, metavar='DIR', help='only aggregate: a sweep '
                      'directory, or a directory of run directories (trials/ or its own)')
    parser.add_argument('--seeds', default='1-5', help='training seeds (default 1-5)')
    parser.add_argument('--grid', action='append', metavar='KEY=V1,V2',
                        help='a setting to vary (training or sim), repeatable: the grid is '
                        'every combination')
    parser.add_argument('--set', action='append', metavar='KEY=V',
                        help='a setting for every trial (training or sim), repeatable')
    parser.add_argument('--total-timesteps', type=int, help='training steps per trial')
    parser.add_argument('--train-seeds', default='101-200',
                        help='training-bank scenarios of the final evaluation')
    parser.add_argument('--heldout-seeds', default='201-300',
                        help='held-out scenarios of the final evaluation')
    parser.add_argument('--curve-seeds', default='201-230', help="held-out scenarios per "
                        "checkpoint for the sample-efficiency curve ('' = none)")
    parser.add_argument('--no-baselines', action='store_true',
                        help='skip the random policy and servo on both banks')
    parser.add_argument('--record', action='store_true', help='write MCAP bags of the final '
                        'evaluation (large: 200 episodes per trial)')
    parser.add_argument('--cpus-per-trial', type=float, default=2)
    parser.add_argument('--gpus-per-trial', type=float, default=0,
                        help='> 0: the trial trains on cuda')
    parser.add_argument('--address', help="attach to a Ray cluster ('auto' or HOST:PORT); "
                        'default: start Ray on this machine for the sweep')
    parser.add_argument('--storage', default='runs', help='directory of the sweep directory '
                        '(on a cluster: a path every node shares)')
    parser.add_argument('--name', help='sweep directory name (default sweep_<date>_<time>)')
    parser.add_argument('--retry-failed', action='store_true',
                        help='with --resume: run failed trials again')
    return parser


def main(argv: list[str] | None = None) -> None:
    """Run ``visnav-sweep``."""
    args = build_parser().parse_args(strip_ros_args(argv))

    def body() -> int:
        if args.aggregate:
            aggregate(args.aggregate.resolve())
            return 0
        if args.resume:
            spec = load_spec(args.resume)
            if args.cpus_per_trial != 2 or args.gpus_per_trial != 0:
                spec.cpus_per_trial, spec.gpus_per_trial = args.cpus_per_trial, args.gpus_per_trial
            return run_sweep(spec, args.address, resume=True, retry_failed=args.retry_failed)
        return run_sweep(spec_from_args(args), args.address, resume=False)

    run_command('visnav-sweep', body)


if __name__ == '__main__':
    sys.exit(main())
