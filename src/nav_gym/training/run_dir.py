"""The layout of a run directory (no ROS, no torch): the one place that spells a run's paths.

Training, evaluation, diagnosis, the report and the sweep all name a run's files through it.

    RUN/config.yaml              the effective TrainConfig (load_config)
    RUN/monitor.csv              SB3 Monitor episodes (read_monitor)
    RUN/summary.json             timing of the training sessions
    RUN/validation.json          the environment checklist (the main job's first stage)
    RUN/tb/                      TensorBoard logs
    RUN/final_model.zip          the model at the end of training
    RUN/checkpoints/             dqn_<steps>_steps.zip (checkpoints) + the latest replay buffer
    RUN/eval/results.json        evaluation results, with results.md and episodes.csv beside it;
                                 traces/<set>/seed_<n>.json + _frames.npz; bags/<set>/ (MCAP);
                                 diagnosis.json, diagnosis.md and figures/; videos/;
                                 curve/<steps>/ (a sweep's evaluation of each checkpoint)
    RUN/eval_closed_loop/        the closed-loop evaluation: lockstep and real time on the same
                                 seeds, laid out as eval/ (results.json, traces/, bags/)
    RUN/report/Result.md         the report, with Result.html, figures/ and videos/
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from nav_gym.errors import TrainConfigError
from nav_gym.training.config import TrainConfig, load_yaml
from nav_gym.training.spec import LEGACY_DEFAULTS

CONFIG = 'config.yaml'
MONITOR = 'monitor.csv'
SUMMARY = 'summary.json'
VALIDATION = 'validation.json'
TENSORBOARD = 'tb'
FINAL_MODEL = 'final_model.zip'
CHECKPOINTS = 'checkpoints'
REPLAY_BUFFER = 'replay_buffer.pkl'
REPLAY_BUFFER_STEP = 'replay_buffer.step'
#: what only a run directory holds (one of them is enough to call a folder a run)
RUN_MARKERS = (SUMMARY, CONFIG, MONITOR)
CHECKPOINT_RE = re.compile(r'dqn_(\d+)_steps\.zip$')
#: the command that continues an interrupted run (followed by its directory)
RESUME_COMMAND = 'nav-gym-train --resume'
# RUN/eval/
EVAL = 'eval'
RESULTS = 'results.json'
RESULTS_TABLE = 'results.md'
EPISODES_CSV = 'episodes.csv'
TRACES = 'traces'
BAGS = 'bags'
DIAGNOSIS = 'diagnosis.json'
DIAGNOSIS_TEXT = 'diagnosis.md'
FIGURES = 'figures'
VIDEOS = 'videos'
CURVE = 'curve'
# RUN/eval_closed_loop/: the closed-loop evaluation (its own results.json, traces, bags)
CLOSED_LOOP = 'eval_closed_loop'
# RUN/report/
REPORT = 'report'
REPORT_TEXT = 'Result.md'
#: the run settings evaluation must share with training (compared by the diagnosis)
EVAL_SETTINGS = ('sim_params', 'forward_speed', 'turn_rate', 'turn_speed', 'max_episode_steps',
                 'progress_weight', 'step_penalty', 'goal_reward', 'collision_penalty')


class RunDirError(TrainConfigError):
    """A directory is not a (readable) training run directory."""


def load_config(run_dir: str | Path) -> TrainConfig:
    """Return the TrainConfig a run was trained with, or raise RunDirError saying what is wrong.

    A config.yaml of an older run (without the settings added since) loads with the values of
    that time for the missing settings (:func:`run_settings`).
    """
    path = Path(run_dir) / CONFIG
    if not path.is_file():
        raise RunDirError(f'{run_dir} is not a training run directory (no {CONFIG}); train one '
                          'with `ros2 run nav_gym train`')
    return TrainConfig(**run_settings(load_yaml(path)))


def run_settings(values: dict[str, Any]) -> dict[str, Any]:
    """Return a run's saved settings with the values of its time for those it does not name.

    A setting added since takes its default, which was its value then, except where the
    default changed since (:data:`LEGACY_DEFAULTS`).
    """
    return {**LEGACY_DEFAULTS, **values}


def is_run_dir(path: Path) -> bool:
    """Tell whether ``path`` is a directory holding one of a run's own files."""
    return Path(path).is_dir() and any((Path(path) / m).is_file() for m in RUN_MARKERS)


def eval_settings(config: TrainConfig) -> dict[str, Any]:
    """Return the settings of ``config`` that evaluation must share with training."""
    return {key: getattr(config, key) for key in EVAL_SETTINGS}


# --- checkpoints -------------------------------------------------------------------------------
def checkpoint_path(run_dir: Path, steps: int) -> Path:
    """Return the path of the checkpoint saved at ``steps`` environment steps."""
    return Path(run_dir) / CHECKPOINTS / f'dqn_{steps}_steps.zip'


def checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """Return (steps, path) of the run's ``checkpoints/dqn_<steps>_steps.zip``, oldest first."""
    found = []
    for path in (Path(run_dir) / CHECKPOINTS).glob('dqn_*_steps.zip'):
        match = CHECKPOINT_RE.search(path.name)
        if match:
            found.append((int(match.group(1)), path))
    return sorted(found)


def on_schedule(steps: int, added: int, every: int) -> bool:
    """Say whether a call that added ``added`` steps and reached ``steps`` passed a checkpoint.

    The schedule is every ``every`` steps; N envs add N steps a call, so a multiple of
    ``every`` is passed, not always met.
    """
    return steps // every > (steps - added) // every


def is_curve_point(steps: int, config: TrainConfig) -> bool:
    """Say whether a run's checkpoint at ``steps`` is a point of its sample-efficiency curve.

    The points are the checkpoints of the schedule (every ``checkpoint_freq`` steps) and the
    finished run's last one (at its total steps, on the schedule or not); not step 0's
    reference, nor a checkpoint that a stop saved between two (that one is for resuming).
    """
    return steps > 0 and (on_schedule(steps, config.n_envs, config.checkpoint_freq)
                          or steps >= config.total_timesteps)


def curve_checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """Return the run's checkpoints that are curve points (:func:`is_curve_point`), in order."""
    config = load_config(run_dir)
    return [(steps, path) for steps, path in checkpoints(run_dir)
            if is_curve_point(steps, config)]


def parse_checkpoint_name(name: str) -> int | None:
    """Return the steps a checkpoint file name carries (None for another name)."""
    match = CHECKPOINT_RE.search(name)
    return int(match.group(1)) if match else None


# --- evaluation --------------------------------------------------------------------------------
def curve_dir(run_dir: Path, steps: int) -> Path:
    """Return where a sweep evaluates the checkpoint of ``steps`` (``eval/curve/<steps>``)."""
    return Path(run_dir) / EVAL / CURVE / str(steps)


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
                on_error: Callable[[Path, Exception], None] | None = None,
                ) -> Iterator[tuple[Path, dict[str, Any]]]:
    """Yield ``(path, trace)`` for the traced episodes of one evaluated set (any order).

    ``seeds``: only these (an earlier evaluation of other seeds leaves its traces in the same
    folder).  A trace that cannot be read or parsed, or names no seed, is skipped, and passed to
    ``on_error`` with the exception when one is given.
    """
    wanted = None if seeds is None else set(seeds)
    for path in trace_files(eval_dir, set_name):
        try:
            trace = json.loads(path.read_text())
            if wanted is not None and trace['seed'] not in wanted:
                continue
        except (OSError, ValueError, KeyError, TypeError) as exc:
            if on_error is not None:
                on_error(path, exc)
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
