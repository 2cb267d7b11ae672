"""What an evaluation runs: named sets of one policy on one split's seeds (no ROS, no torch)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from nav_eval.errors import EvaluationError
from nav_gym.errors import TrainConfigError
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import FINAL_MODEL, checkpoints, load_config
from nav_sim.core.config import TRAIN, normalise_split

SET_LABELS = {
    'random_train': 'Random policy, training seeds', 'dqn_train': 'DQN final, training seeds',
    'dqn_heldout': 'DQN final, held-out seeds', 'early_train': 'DQN early, training seeds',
    'early_heldout': 'DQN early, held-out seeds',
    # a diagnosis, not in the defaults: the final model with training's final exploration
    'explore_train': 'DQN final with training ε, training seeds',
    'explore_heldout': 'DQN final with training ε, held-out seeds'}
#: the workshop's evaluation: deterministic policies only
DEFAULT_SETS = ('random_train', 'dqn_train', 'dqn_heldout', 'early_train', 'early_heldout')
#: the baselines of a sweep's configurations, each on both splits (``<policy>_<split>`` sets)
BASELINE_POLICIES = ('random', 'servo', 'oracle')

#: evaluation set kind (its name's first word) -> the policy that plays it
SET_POLICIES = {'random': 'random', 'dqn': 'dqn', 'early': 'dqn', 'explore': 'explore'}


@dataclass(frozen=True)
class EvalSet:
    """A policy evaluated on one split's seeds."""

    name: str
    label: str
    policy: str
    checkpoint: str | None
    split: str
    seeds: tuple[int, ...]


def run_config(run_dir: Path) -> TrainConfig:
    """Return the run's TrainConfig, or raise EvaluationError saying what is wrong."""
    try:
        return load_config(run_dir)
    except TrainConfigError as exc:
        raise EvaluationError(str(exc)) from None


def early_checkpoint(run_dir: Path) -> str | None:
    """Return the first checkpoint after step 0 (relative to the run directory), if any."""
    found = [(s, p) for s, p in checkpoints(run_dir) if s > 0]
    return str(found[0][1].relative_to(run_dir)) if found else None


def plan_sets(run_dir: Path, names: list[str], train_seeds: tuple[int, ...],
              heldout_seeds: tuple[int, ...], final: str = FINAL_MODEL,
              early: str | None = None) -> list[EvalSet]:
    """Return the evaluation sets to run, in the order given; raise on unknown names."""
    run_config(run_dir)  # a clear error first if this is not a run directory
    unknown = [n for n in names if n not in SET_LABELS]
    if unknown:
        raise EvaluationError(f'unknown evaluation set(s) {unknown}; known: {list(SET_LABELS)}')
    early = early or early_checkpoint(run_dir)
    out = []
    for name in names:
        kind, split_name = name.split('_')
        split = normalise_split(split_name)
        seeds = train_seeds if split == TRAIN else heldout_seeds
        if kind == 'early' and early is None:
            print(f'skipping {name}: the run has no checkpoint after step 0')
            continue
        checkpoint = {'random': None, 'dqn': final, 'early': early, 'explore': final}[kind]
        if checkpoint is not None and not (run_dir / checkpoint).is_file():
            raise EvaluationError(f'{name}: checkpoint {run_dir / checkpoint} not found; '
                                  'finish (or --resume) the training run first')
        out.append(EvalSet(name, SET_LABELS[name], SET_POLICIES[kind], checkpoint, split, seeds))
    return out
