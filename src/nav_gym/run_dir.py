"""The layout of a run directory (no ROS, no torch), in one place.

Training, evaluation, diagnosis and the report share it, as they share :mod:`nav_gym.checkpoints`
for checkpoint names.

    RUN/config.yaml            the effective TrainConfig (load_config)
    RUN/monitor.csv            SB3 Monitor episodes (read_monitor)
    RUN/summary.json           timing of the training sessions
    RUN/final_model.zip        the model at the end of training
    RUN/checkpoints/           dqn_<steps>_steps.zip + the latest replay buffer (resume only)
    RUN/eval/results.json      evaluation results; eval/traces/<set>/seed_<n>.json + _frames.npz
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from nav_gym.errors import TrainConfigError
from nav_gym.train_config import TrainConfig, load_yaml

CONFIG = 'config.yaml'
MONITOR = 'monitor.csv'
SUMMARY = 'summary.json'
FINAL_MODEL = 'final_model.zip'
CHECKPOINTS = 'checkpoints'
REPLAY_BUFFER = 'replay_buffer.pkl'
REPLAY_BUFFER_STEP = 'replay_buffer.step'
EVAL = 'eval'
RESULTS = 'results.json'
TRACES = 'traces'
#: the run settings evaluation must share with training (compared by the diagnosis)
EVAL_SETTINGS = ('sim_params', 'forward_speed', 'turn_rate', 'turn_speed', 'max_episode_steps',
                 'progress_weight', 'step_penalty', 'goal_reward', 'collision_penalty')


class RunDirError(TrainConfigError):
    """A directory is not a (readable) training run directory."""


def load_config(run_dir: str | Path) -> TrainConfig:
    """Return the TrainConfig a run was trained with, or raise RunDirError saying what is wrong.

    A config.yaml of an older run (without the settings added since) loads with the defaults
    of the missing settings, which were the values of that time.
    """
    path = Path(run_dir) / CONFIG
    if not path.is_file():
        raise RunDirError(f'{run_dir} is not a training run directory (no {CONFIG}); train one '
                          'with `ros2 run nav_gym train`')
    return TrainConfig(**load_yaml(path))


def eval_settings(config: TrainConfig) -> dict[str, Any]:
    """Return the settings of ``config`` that evaluation must share with training."""
    return {key: getattr(config, key) for key in EVAL_SETTINGS}


def trace_path(eval_dir: Path, set_name: str, seed: int) -> Path:
    """Return the path of the JSON trace of one evaluated episode."""
    return Path(eval_dir) / TRACES / set_name / f'seed_{seed}.json'


def frames_path(trace: Path) -> Path:
    """Return the path of the observations (``obs``: (T, 3, 84, 84) uint8) of a trace."""
    return trace.with_name(f'{trace.stem}_frames.npz')


def trace_files(eval_dir: Path, set_name: str) -> list[Path]:
    """Return the trace files of one evaluated set (any order)."""
    return list((Path(eval_dir) / TRACES / set_name).glob('seed_*.json'))


def read_traces(eval_dir: Path, set_name: str, seeds: Iterable[int] | None = None,
                ) -> Iterator[tuple[Path, dict[str, Any]]]:
    """Yield ``(path, trace)`` for the traced episodes of one evaluated set (any order).

    ``seeds``: only these (an earlier evaluation of other seeds leaves its traces in the same
    folder).  A trace that cannot be read or parsed, or names no seed, is skipped.
    """
    wanted = None if seeds is None else set(seeds)
    for path in trace_files(eval_dir, set_name):
        try:
            trace = json.loads(path.read_text())
            if wanted is not None and trace['seed'] not in wanted:
                continue
        except (OSError, ValueError, KeyError, TypeError):
            continue
        yield path, trace


def read_monitor(path: Path) -> dict[str, list[str]]:
    """Read the episodes of an SB3 Monitor CSV as columns of strings.

    Columns: ``r``, ``l``, ``t`` and any logged info keys; comment lines and the header lines
    a resumed run repeats are skipped.
    """
    with open(path, newline='') as handle:
        lines = [line for line in handle if line.strip() and not line.startswith('#')]
    header = next(csv.reader(lines[:1]), ['r', 'l', 't'])
    columns: dict[str, list[str]] = {key: [] for key in header}
    for row in csv.reader(lines[1:]):
        if row == header:
            continue
        for key, value in zip(header, row, strict=False):
            columns[key].append(value)
    return columns


def truthy(value: str | None) -> bool:
    """Tell whether a Monitor CSV value spells True (``True``, ``1``, ``1.0``)."""
    return str(value).strip().lower() in ('true', '1', '1.0')
