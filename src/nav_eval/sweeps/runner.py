"""Run a sweep's trials on Ray Tune (:mod:`nav_eval.sweeps.tune`) and aggregate them."""

from __future__ import annotations

import json
import shutil
from functools import partial
from pathlib import Path

from nav_eval.errors import SweepError
from nav_eval.sweeps.report import write_sweep_report
from nav_eval.sweeps.spec import (
    FAILED_FILE,
    SUMMARY_FILES,
    SWEEP_FIGURES,
    SWEEP_REPORT,
    SweepSpec,
    check_summary,
    read_json,
    summary_swap,
)
from nav_eval.sweeps.trial import trial_finished

INTERRUPTED = 130


def run_sweep(spec: SweepSpec, address: str | None, resume: bool,
              retry_failed: bool = False) -> int:
    """Run (or continue) the sweep's trials on Ray Tune; aggregate; return an exit code."""
    from nav_eval.sweeps.tune import run_trials  # Ray: only when trials run
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
    keep = partial(keep_summary, Path(spec.sweep_dir), Path(spec.summary), spec.sweep_id) \
        if spec.summary else None
    outcome = run_trials(spec, trials, address, resume, retry_failed, done, after_each=keep)
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
    if keep is not None:  # aggregates, then writes the summary
        keep()
    else:
        aggregate(Path(spec.sweep_dir))
    return 1 if outcome.failed else 0


def _read_failures(path: Path) -> dict[str, str]:
    data = read_json(path)
    return data if isinstance(data, dict) else {}


def aggregate(folder: Path) -> Path:
    """Write Sweep.md, Sweep.html, results.json and figures/ of the finished trials."""
    path = write_sweep_report(folder)
    print(f'sweep report: {path} (+ Sweep.html, results.json)', flush=True)
    return path


def export(sweep_dir: Path, destination: Path) -> Path:
    """Copy a sweep's summary form (``spec.SUMMARY_FILES``) to ``destination``; return it.

    The form docs/sweeps commits: Sweep.md, results.json, sweep.json, figures/ and configs/
    (no trials, logs, baselines or Tune state); the figures as palette PNGs
    (:func:`palette_png`).  ``destination`` must not exist yet.
    """
    if not (sweep_dir / SWEEP_REPORT).is_file():
        raise SweepError(f'{sweep_dir} has no {SWEEP_REPORT}: aggregate it first with '
                         f'`visnav-sweep --aggregate {sweep_dir}`')
    if destination.exists():
        raise SweepError(f'{destination} exists: choose a new folder for the summary')
    destination.mkdir(parents=True)
    for name in SUMMARY_FILES:
        source = sweep_dir / name
        if name == SWEEP_FIGURES and source.is_dir():
            for figure in sorted(source.glob('*.png')):
                palette_png(figure, destination / name / figure.name)
        elif source.is_dir():
            shutil.copytree(source, destination / name)
        elif source.is_file():
            shutil.copy2(source, destination / name)
    return destination


def keep_summary(sweep_dir: Path, destination: Path, sweep_id: str) -> Path:
    """Aggregate the sweep's finished trials and replace ``destination`` with its summary form.

    ``--summary DEST``: the sweep calls it after each trial that completes, so that what has
    finished outlives a checkout that does not keep ``runs/``.  The new summary is written
    beside ``destination`` and swapped in, so a stop at any moment leaves a whole one (or,
    between the two renames, the old one beside it, which the next check puts back).  A folder
    that is not this sweep's summary (``sweep_id``) is never replaced.
    """
    aggregate(sweep_dir)
    check_summary(destination, sweep_id)
    fresh, old = summary_swap(destination)
    for leftover in (fresh, old):
        shutil.rmtree(leftover, ignore_errors=True)
    export(sweep_dir, fresh)
    if destination.exists():
        destination.rename(old)
    fresh.rename(destination)
    shutil.rmtree(old, ignore_errors=True)
    print(f'sweep summary: {destination}', flush=True)
    return destination


def palette_png(source: Path, destination: Path) -> Path:
    """Write a figure as a 256-colour palette PNG (about 40 % of the size; plots look the same).

    The sweep's figures are flat-coloured line plots with anti-aliased edges: a median-cut
    palette without dithering keeps every curve, band and label.
    """
    from PIL import Image  # matplotlib's dependency
    destination.parent.mkdir(parents=True, exist_ok=True)
    with Image.open(source) as image:
        palette = image.convert('RGB').quantize(colors=256, method=Image.Quantize.MEDIANCUT,
                                                dither=Image.Dither.NONE)
    palette.save(destination, 'PNG', optimize=True)
    return destination
