"""A run directory's inputs to its report: the files read once, the sets, traces and examples."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from nav_eval.errors import DiagnosisError, ReportError
from nav_eval.evaluation.selection import pick_episode
from nav_eval.reporting.format import (
    display_path,
)
from nav_gym.training.run_dir import (
    CLOSED_LOOP,
    CONFIG,
    DIAGNOSIS,
    EVAL,
    FIGURES,
    REPORT,
    RESULTS,
    RUN_MARKERS,
    SUMMARY,
    VALIDATION,
    is_run_dir,
    read_traces,
)
from nav_sim.core.config import HELDOUT, TRAIN
from nav_sim.core.events import OUTCOME_SUCCESS


@dataclass
class Run:
    """A run directory's inputs, each None when missing or unreadable (``problems`` says)."""

    path: Path
    figures: Path
    shown: str
    summary: dict[str, Any] | None = None
    config: dict[str, Any] | None = None
    validation: list[dict[str, Any]] | None = None
    results: dict[str, Any] | None = None
    closed_loop: dict[str, Any] | None = None
    diagnosis: dict[str, Any] | None = None
    problems: list[str] = field(default_factory=list)

    def read(self, relative: str) -> Any:
        """Load a JSON or YAML file of the run; None if absent, noted in ``problems`` if bad."""
        path = self.path / relative
        if not path.is_file():
            return None
        try:
            text = path.read_text()
            return yaml.safe_load(text) if path.suffix == '.yaml' else json.loads(text)
        except (OSError, ValueError, yaml.YAMLError) as exc:
            self.problems.append(f'`{relative}` could not be read ({type(exc).__name__}: {exc})')
            return None

    def sets(self) -> list[dict[str, Any]]:
        """Return the evaluated sets of ``eval/results.json`` (empty when there are none)."""
        return list((self.results or {}).get('sets', []))

    def figure(self, name: str) -> tuple[Path, str]:
        """Where a figure is written and how Result.md refers to it."""
        return self.figures / name, f'{FIGURES}/{name}'


def load_run(run_dir: Path) -> Run:
    """Read a run directory's inputs; raise ReportError if it is not a run directory."""
    run_dir = Path(run_dir)
    if not is_run_dir(run_dir):
        raise ReportError(f'{run_dir} is not a run directory (it has none of '
                          f'{", ".join(RUN_MARKERS)}); pass the directory nav-gym-train created, '
                          'e.g. runs/dqn_20261122_101500')
    run = Run(run_dir, run_dir / REPORT / FIGURES,
              display_path(run_dir, f'runs/{run_dir.resolve().name}'))
    run.summary = run.read(SUMMARY)
    run.config = (run.summary or {}).get('config') or run.read(CONFIG)
    run.validation = run.read(VALIDATION)
    run.results = run.read(f'{EVAL}/{RESULTS}')
    run.closed_loop = run.read(f'{CLOSED_LOOP}/{RESULTS}')
    run.diagnosis = run.read(f'{EVAL}/{DIAGNOSIS}')
    return run


def final_set(run: Run, split: str, seeds: list[int] | None = None) -> dict[str, Any] | None:
    """Return the final DQN set on a split, or None.

    Sets with the same ``seeds`` come first, then the one named ``dqn_<split>``.
    """
    found = [s for s in run.sets() if s.get('policy') == 'dqn' and s.get('split') == split
             and not str(s.get('name', '')).startswith('early_')]
    found.sort(key=lambda s: (sorted(s.get('seeds', [])) != sorted(seeds or []),
                              s.get('name') != f'dqn_{split}'))
    return found[0] if found else None


def load_traces(run: Run, set_name: str) -> list[tuple[Path, dict[str, Any]]]:
    """Return the traces of one evaluated set, by seed; an unreadable one is a noted problem."""
    def unreadable(path: Path, exc: Exception) -> None:
        run.problems.append(f'`{path.relative_to(run.path)}` could not be read '
                            f'({type(exc).__name__}: {exc})')

    found = [(path, trace) for path, trace in read_traces(run.path / EVAL, set_name,
                                                          on_error=unreadable)
             if isinstance(trace, dict) and 'scenario' in trace]
    return sorted(found, key=lambda item: item[1].get('seed', 0))


def dqn_sets_for_examples(run: Run) -> list[dict[str, Any]]:
    """Return the final DQN sets to take examples from: held-out first, then train."""
    return [s for s in (final_set(run, HELDOUT), final_set(run, TRAIN)) if s]


def pick_examples(run: Run) -> tuple[Any, Any]:
    """Pick a successful and a failed (path, trace) pair of the final DQN, each or None.

    The failure is the diagnosed episode when its trace exists (the early checkpoint's when the
    final model never failed), else the first failure.
    """
    traces = [t for s in dqn_sets_for_examples(run) for t in load_traces(run, s['name'])]
    success = next((t for t in traces if t[1].get('outcome') == OUTCOME_SUCCESS), None)
    diagnosis = run.diagnosis or {}
    failures = [t for t in traces if t[1].get('outcome') != OUTCOME_SUCCESS]
    failed = next((t for t in failures if t[1].get('set') == diagnosis.get('set')
                   and t[1].get('seed') == diagnosis.get('seed')), None)
    if failed is None and not failures and diagnosis.get('set'):
        # the final model failed nowhere: the diagnosed failure is the early checkpoint's
        failed = next((t for t in load_traces(run, diagnosis['set'])
                       if t[1].get('seed') == diagnosis.get('seed')), None)
    return success, failed or (failures[0] if failures else None)


def diagnosed_episode(run: Run) -> tuple[str, int, str] | None:
    """Name the diagnosed episode: (set, seed, how the report calls it).

    From ``eval/diagnosis.json``; before there is one, the episode ``nav-eval-diagnose`` picks
    by default; None when there is no failure to diagnose.
    """
    diagnosis = run.diagnosis or {}
    if diagnosis.get('set') is not None and diagnosis.get('seed') is not None:
        return str(diagnosis['set']), int(diagnosis['seed']), 'diagnosed'
    try:
        return (*pick_episode(run.path / EVAL, None, None), 'to diagnose')
    except (DiagnosisError, KeyError, TypeError, ValueError):
        return None


def video_episodes(run: Run) -> list[tuple[str, Path, dict[str, Any]]]:
    """List the episodes to show as videos: (caption, trace path, trace).

    The report's success and failure examples (``pick_examples``) and the diagnosed episode,
    each once.
    """
    success, failed = pick_examples(run)
    chosen = [(role, *example) for role, example in (('Success', success), ('Failure', failed))
              if example is not None]
    diagnosed = diagnosed_episode(run)
    if diagnosed is not None:
        set_name, seed, how = diagnosed
        same = [i for i, (_, _, t) in enumerate(chosen) if (t.get('set'), t.get('seed'))
                == (set_name, seed)]
        if same:
            role, path, trace = chosen[same[0]]
            chosen[same[0]] = (f'{role} ({how})', path, trace)
        else:
            chosen += [(how.capitalize(), path, trace)
                       for path, trace in load_traces(run, set_name) if trace.get('seed') == seed]
    return [(f"{role}: {t.get('set')} seed {t.get('seed')} ({t.get('outcome')}, "
             f"{len(t.get('steps', []))} steps)", path, t) for role, path, t in chosen]
