"""Which evaluated episode a diagnosis (and the report's example) looks at, and its evidence."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from nav_eval.errors import DiagnosisError
from nav_gym.training.run_dir import RESULTS, TRACES, frames_path, trace_path
from nav_sim.core.events import OUTCOME_SUCCESS

# the final model's failures first; if it fails nowhere, the early checkpoint's
SEARCH_ORDER = ('dqn_heldout', 'dqn_train', 'early_heldout', 'early_train')


def pick_episode(eval_dir: Path, set_name: str | None, seed: int | None) -> tuple[str, int]:
    """Return the (set, seed) to diagnose: as given, or the first failure in ``SEARCH_ORDER``."""
    results_path = eval_dir / RESULTS
    if not results_path.is_file():
        raise DiagnosisError(f'no evaluation in {eval_dir}; run `ros2 run nav_eval evaluate '
                             f'{eval_dir.parent}` first')
    sets = {s['name']: s for s in json.loads(results_path.read_text())['sets']}
    names = [set_name] if set_name else [n for n in SEARCH_ORDER if n in sets]
    for name in names:
        if name not in sets:
            raise DiagnosisError(f'no evaluation set {name!r} in {results_path}; have '
                                 f'{sorted(sets)}')
        for e in sets[name]['episodes']:
            if (seed is None and e['outcome'] != OUTCOME_SUCCESS) or e['seed'] == seed:
                return name, e['seed']
    if seed is not None:
        raise DiagnosisError(f'seed {seed} is not in set(s) {names}')
    raise DiagnosisError(f'no failed episode in {names}: nothing to diagnose')


def load_episode(eval_dir: Path, set_name: str, seed: int) -> tuple[dict, np.ndarray]:
    """Return the trace and the observations of one evaluated episode."""
    trace_file = trace_path(eval_dir, set_name, seed)
    frames_file = frames_path(trace_file)
    if not (trace_file.is_file() and frames_file.is_file()):
        raise DiagnosisError(f'no trace for {set_name} seed {seed} in '
                             f'{eval_dir / TRACES}; re-run the evaluation')
    with np.load(frames_file) as data:
        frames = data['obs']
    return json.loads(trace_file.read_text()), frames
