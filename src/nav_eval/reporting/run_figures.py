"""A run report's figures: drawn (or copied) into ``report/figures/`` before its text is built.

:func:`draw_figures` makes every figure the report shows and returns a :class:`Figures` that
says what was made and how the text refers to it; the sections of
:mod:`nav_eval.reporting.run_report` then only write text.  The rollout videos are the video
module's (:func:`nav_eval.reporting.videos.write_run_videos`).  Where the inputs of a section's
figures are malformed, the error is kept for that section's text instead of failing the report.
"""

from __future__ import annotations

import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.reporting import plots
from nav_eval.reporting.format import IMAGE_RE
from nav_eval.reporting.run_inputs import Run, dqn_sets_for_examples, load_traces, pick_examples
from nav_gym.training.run_dir import (
    DIAGNOSIS_TEXT,
    EVAL,
    FIGURES,
    MONITOR,
    frames_path,
)

#: what a malformed input raises while its figure is drawn (the section says so instead)
MALFORMED = (OSError, ValueError, KeyError, IndexError, TypeError)
TRAINING, TRAJECTORIES, DIAGNOSIS, EXPERIMENTS = 2, 5, 6, 7  # the sections that show figures


@dataclass
class Example:
    """A trajectory example drawn for the report: which episode, and its figure."""

    kind: str                  # 'success' or 'failure'
    trace: dict[str, Any]
    ref: str                   # how Result.md refers to the figure


@dataclass
class Figures:
    """What :func:`draw_figures` made, for the sections to describe."""

    training_curves: str | None = None          # ref; None without monitor.csv
    grid: tuple[str, str] | None = None          # (ref, the set's name); None without traces
    examples: dict[str, Example | None] = field(default_factory=dict)
    contact_sheet: tuple[str, str] | None = None  # (ref, caption); None without frames
    included: dict[Path, list[str]] = field(default_factory=dict)  # Markdown, relinked
    diagnosis_figures: list[tuple[str, str | None]] = field(default_factory=list)  # (name, ref)
    errors: dict[int, str] = field(default_factory=dict)  # section number -> what failed


def draw_figures(run: Run, experiments: Path | None) -> Figures:
    """Draw every figure of the report into ``run.figures`` (which exists)."""
    figures = Figures()
    for section, draw in ((TRAINING, _draw_training), (TRAJECTORIES, _draw_trajectories),
                          (DIAGNOSIS, _copy_diagnosis),
                          (EXPERIMENTS, lambda r, f: _include(r, f, experiments, 'experiments'))):
        try:
            draw(run, figures)
        except MALFORMED as exc:
            figures.errors[section] = f'{type(exc).__name__}: {exc}'
    return figures


def _draw_training(run: Run, figures: Figures) -> None:
    if (run.path / MONITOR).is_file():
        out, figures.training_curves = run.figure('training_curves.png')
        plots.training_curves(run.path, out)


def _draw_trajectories(run: Run, figures: Figures) -> None:
    arena = (run.results or {}).get('arena')
    sets = dqn_sets_for_examples(run)
    grid = [t for _, t in load_traces(run, sets[0]['name'])] if sets else []
    if not arena or not grid:
        return
    name = sets[0].get('label') or sets[0]['name']
    out, ref = run.figure('trajectory_grid.png')
    plots.trajectory_grid(grid, arena, out, title=f'{name}: first {min(len(grid), 10)} episodes')
    figures.grid = ref, name
    success, failed = pick_examples(run)
    for kind, example in (('success', success), ('failure', failed)):
        figures.examples[kind] = None
        if example is not None:
            out, ref = run.figure(f'trajectory_{kind}.png')
            plots.trajectory(example[1], arena, out)
            figures.examples[kind] = Example(kind, example[1], ref)
    # the diagnosis already shows the failure's frames: then show the success's
    order = (success, failed) if (run.diagnosis or {}).get('figures') else (failed, success)
    for path, trace in (e for e in order if e):
        frames_file = frames_path(path)
        if not frames_file.is_file():
            continue
        with np.load(frames_file) as archive:
            frames = archive['obs']
        out, ref = run.figure('contact_sheet.png')
        caption = (f"Policy observations (3x84x84) of {trace.get('set')} seed "
                   f"{trace.get('seed')} ({trace.get('outcome')}); each frame is labelled with "
                   'the step and action that produced it')
        plots.contact_sheet(frames, out, labels=plots.frame_labels(trace.get('steps', [])),
                            title=caption)
        figures.contact_sheet = ref, caption
        return


def _copy_diagnosis(run: Run, figures: Figures) -> None:
    source = run.path / EVAL / DIAGNOSIS_TEXT
    if source.is_file():
        _include(run, figures, source, 'diagnosis')
    shown = '\n'.join(figures.included.get(source, []))
    for figure in (run.diagnosis or {}).get('figures', []):
        found = run.path / figure
        name = found.name if found.name.startswith('diagnosis') else f'diagnosis_{found.name}'
        if not found.is_file():
            figures.diagnosis_figures.append((figure, None))
        elif f'{FIGURES}/{name})' not in shown:
            out, ref = run.figure(name)
            shutil.copyfile(found, out)
            figures.diagnosis_figures.append((figure, ref))


def _include(run: Run, figures: Figures, source: Path | None, prefix: str) -> None:
    """Keep a Markdown file's lines, its relative images copied into the report's figures."""
    if source is None or not Path(source).is_file():
        return
    source = Path(source)

    def relink(match: re.Match[str]) -> str:
        target = match.group(2)
        for base in (source.parent, run.path):
            found = base / target
            if not re.match(r'[a-z]+:', target) and found.is_file():
                name = found.name if found.name.startswith(prefix) else f'{prefix}_{found.name}'
                out, ref = run.figure(name)
                shutil.copyfile(found, out)
                return f'![{match.group(1)}]({ref})'
        return match.group(0)
    figures.included[source] = [IMAGE_RE.sub(relink, source.read_text()).rstrip(), '']
