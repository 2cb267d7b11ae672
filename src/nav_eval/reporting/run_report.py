"""A run's result report (Markdown + self-contained HTML) with its figures and videos.

Reads what the other commands left in RUN_DIR (validation.json, summary.json, monitor.csv,
checkpoints/, eval/results.json, eval/traces/, eval/diagnosis.*, eval_closed_loop/results.json)
and writes
RUN_DIR/report/Result.md, RUN_DIR/report/Result.html, RUN_DIR/report/figures/*.png and the
rollout videos RUN_DIR/report/videos/*.mp4 (:mod:`nav_eval.reporting.videos`).  Every section is
written; one whose input is missing says which command produces it.
"""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from nav_eval.errors import DiagnosisError, ReportError
from nav_eval.evaluation.selection import pick_episode
from nav_eval.reporting import plots, videos
from nav_eval.reporting.closed_loop import section_closed_loop
from nav_eval.reporting.format import (
    IMAGE_RE,
    details,
    display_path,
    duration,
    image,
    missing,
    num,
    pct,
    table,
    to_html,
    video_link,
)
from nav_gym.run_dir import (
    CLOSED_LOOP,
    CONFIG,
    DIAGNOSIS,
    DIAGNOSIS_TEXT,
    EVAL,
    FIGURES,
    FINAL_MODEL,
    MONITOR,
    REPORT,
    REPORT_TEXT,
    RESULTS,
    RUN_MARKERS,
    SUMMARY,
    VALIDATION,
    VIDEOS,
    frames_path,
    is_run_dir,
    parse_checkpoint_name,
    read_traces,
    run_settings,
)
from nav_gym.train_config import learner_of

SECTIONS = ('1. Observation and action checks', '2. Training',
            '3. Early vs final checkpoint comparison', '4. Evaluation',
            '5. Representative trajectories', '6. Failure diagnosis',
            '7. Attempts and targeted improvements', '8. Reproduce')
HYPERPARAMETERS = ('double_q', 'n_steps', 'dueling', 'augment_shift', 'prioritized_replay',
                   'priority_alpha', 'priority_beta', 'learning_rate', 'buffer_size',
                   'learning_starts', 'batch_size', 'gamma', 'train_freq', 'gradient_steps',
                   'target_update_interval', 'exploration_fraction', 'exploration_initial_eps',
                   'exploration_final_eps', 'seed', 'split', 'max_episode_steps', 'forward_speed',
                   'turn_rate', 'turn_speed', 'sim_params')
EVAL_COLUMNS = ('Set', 'Policy', 'Split', 'Episodes', 'Success rate', 'Collision rate',
                'Timeout rate', 'Mean length', 'Mean SPL', 'Mean return')


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


# --- sections -----------------------------------------------------------------------------------

def section_checks(run: Run) -> list[str]:
    """Build section 1: the environment validation checklist from ``validation.json``."""
    if not run.validation:
        return missing('`validation.json` (the environment validation checklist)',
                       f'nav-gym-validate --json {run.shown}/validation.json')
    rows = [[c.get('name'), c.get('expected'), c.get('measured'),
             'pass' if c.get('passed') else '**FAIL**'] for c in run.validation]
    failed = sum(not c.get('passed') for c in run.validation)
    names = ' '.join(str(c.get('name')) for c in run.validation)
    lines = [f'{len(rows) - failed} of {len(rows)} checks passed (from `validation.json`, '
             'measured on the running environment by `nav-gym-validate`).', '']
    if 'check_env' not in names:
        lines += ['> **Missing:** no `check_env()` row in `validation.json`.', '']
    return lines + table(['Check', 'Expected', 'Measured', 'Result'], rows)


def section_training(run: Run) -> list[str]:
    """Build section 2: training information, hyperparameters and the training curves."""
    lines: list[str] = []
    summary, config = run.summary or {}, run.config or {}
    if not run.summary:
        lines += missing('`summary.json` (wall-clock time, steps/s)', 'nav-gym-train')
    else:
        sessions = summary.get('sessions') or [summary]
        rows = [['Environment steps', f"{summary.get('num_timesteps', 0):,} of "
                 f"{summary.get('total_timesteps', 0):,}"],
                ['Wall-clock time', duration(summary.get('wall_clock_total_s',
                                                         summary.get('wall_clock_s')))],
                ['Steps per second (last session)', num(summary.get('steps_per_s'), 1)],
                ['Environment share of the time', f"{pct(summary.get('env_share'), 1)} "
                 f"({num(summary.get('env_time_s'), 0)} s in the environment)"],
                ['Episodes (last session)', summary.get('episodes')],
                ['Sessions', f"{len(sessions)} (interrupted: "
                 f"{'yes' if summary.get('interrupted') else 'no'})"]]
        lines += ['**Training information**', ''] + table(['Item', 'Value'], rows)
    if config:
        settings = run_settings(config)
        rows = [[key, json.dumps(settings[key]) if isinstance(settings[key], dict)
                 else settings[key]] for key in HYPERPARAMETERS if key in settings]
        lines += [f'**Learner:** {learner_of(settings).describe()}, `CnnPolicy`.', '',
                  '**Hyperparameters**', ''] + table(['Setting', 'Value'], rows)
    if not (run.path / MONITOR).is_file():
        return lines + missing('`monitor.csv` (episode returns and lengths)', 'nav-gym-train')
    data = plots.monitor_arrays(run.path / MONITOR)
    out, ref = run.figure('training_curves.png')
    plots.training_curves(run.path, out)
    ckpts = ', '.join(f'{s:,}' for s in plots.checkpoint_steps(run.path)) or 'none'
    lines += image(ref, 'Training curves: episode return, length and success/collision rate vs '
                   'environment interactions; dashed lines mark checkpoints')
    count = len(data['r'])
    total = int(data['steps'][-1]) if count else 0
    lines += [f'`monitor.csv` holds {count} episodes over {total:,} environment steps; '
              f'checkpoints at steps: {ckpts}.']
    if count:
        tail = slice(-plots.smoothing_window(count), None)
        rate = (f", success rate {pct(np.mean(data['is_success'][tail]))}"
                if 'is_success' in data else '')
        lines += [f"Last {len(data['r'][tail])} episodes: mean return "
                  f"{np.mean(data['r'][tail]):.2f}, mean length {np.mean(data['l'][tail]):.1f}"
                  f'{rate}.']
    return lines + ['']


def checkpoint_name(entry: dict[str, Any]) -> str:
    """Name the policy of an evaluated set: its checkpoint file (with steps) or random."""
    if entry.get('policy') not in ('dqn', 'explore'):
        return 'random policy'
    name = Path(str(entry.get('checkpoint') or FINAL_MODEL)).name
    steps = parse_checkpoint_name(name)
    name = f'{name} ({steps:,} steps)' if steps is not None else name
    return name if entry.get('policy') == 'dqn' else f"{name}, ε = {entry.get('epsilon')}"


def summary_row(entry: dict[str, Any]) -> list[Any]:
    """Return an evaluated set's row of the evaluation table (``EVAL_COLUMNS``)."""
    s = entry.get('summary', {})
    return [entry.get('label') or entry.get('name'), checkpoint_name(entry), entry.get('split'),
            s.get('episodes'), pct(s.get('success_rate')), pct(s.get('collision_rate')),
            pct(s.get('timeout_rate')), num(s.get('mean_length'), 1),
            num(s.get('mean_spl'), 3), num(s.get('mean_return'), 3)]


def final_set(run: Run, split: str, seeds: list[int] | None = None) -> dict[str, Any] | None:
    """Return the final DQN set on a split, or None.

    Sets with the same ``seeds`` come first, then the one named ``dqn_<split>``.
    """
    found = [s for s in run.sets() if s.get('policy') == 'dqn' and s.get('split') == split
             and not str(s.get('name', '')).startswith('early_')]
    found.sort(key=lambda s: (sorted(s.get('seeds', [])) != sorted(seeds or []),
                              s.get('name') != f'dqn_{split}'))
    return found[0] if found else None


def section_early(run: Run) -> list[str]:
    """Build section 3: each early checkpoint set against the final DQN, seed by seed."""
    early = [s for s in run.sets() if str(s.get('name', '')).startswith('early_')]
    if not early:
        return missing('an `early_*` set in `eval/results.json` (an early checkpoint evaluated on '
                       'the same seeds as the final model)', f'nav-eval-evaluate {run.shown}')
    rows, lines = [], []
    for entry in early:
        final = final_set(run, entry.get('split'), entry.get('seeds'))
        rows.append(summary_row(entry))
        if final is None:
            lines.append(f"No final DQN set on the {entry.get('split')} split to compare "
                         f"`{entry.get('name')}` with.")
            continue
        rows.append(summary_row(final))
        same = sorted(entry.get('seeds', [])) == sorted(final.get('seeds', []))
        lines.append(f"{entry.get('split')} split: success rate "
                     f"{pct(entry['summary'].get('success_rate'))} with "
                     f"{checkpoint_name(entry)} vs {pct(final['summary'].get('success_rate'))} "
                     f"with {checkpoint_name(final)}"
                     f"{' on the same seeds' if same else ' (DIFFERENT seeds: not like for like)'}"
                     '.')
        outcomes = {e['seed']: [e.get('outcome')] for e in entry.get('episodes', [])}
        for e in final.get('episodes', []):
            outcomes.setdefault(e['seed'], ['–']).append(e.get('outcome'))
        rows_by_seed = [[seed, *o, '–'][:3] for seed, o in sorted(outcomes.items())]
        lines += [''] + details(f"Per-seed outcomes: {entry.get('name')} vs {final.get('name')}",
                                table(['Seed', 'Early', 'Final'], rows_by_seed))
    return table(EVAL_COLUMNS, rows) + lines + ['']


def section_evaluation(run: Run) -> list[str]:
    """Build section 4: the evaluation table, the missing required sets and each set's episodes."""
    if not run.sets():
        return missing('`eval/results.json` (deterministic evaluation)',
                       f'nav-eval-evaluate {run.shown}')
    lines = ['Deterministic evaluation (`deterministic=True`) on fixed seeds. SPL: success '
             'weighted by (straight-line distance / path length).', '']
    lines += table(EVAL_COLUMNS, [summary_row(s) for s in run.sets()])
    needed = [('random policy on training seeds', [s for s in run.sets()
                                                   if s.get('policy') == 'random'
                                                   and s.get('split') == 'train']),
              ('final DQN on training seeds', final_set(run, 'train')),
              ('final DQN on held-out seeds', final_set(run, 'heldout'))]
    for what, present in needed:
        if not present:
            lines += [f'> **Missing:** {what}. Produce it with `nav-eval-evaluate {run.shown}`.',
                      '']
    header = ['Seed', 'Outcome', 'Length', 'Return', 'Initial distance (m)',
              'Final distance (m)', 'Path length (m)', 'SPL']
    for entry in run.sets():
        rows = [[e.get('seed'), e.get('outcome'), e.get('length'), num(e.get('return')),
                 num(e.get('initial_distance')), num(e.get('final_distance')),
                 num(e.get('path_length')), num(e.get('spl'))] for e in entry.get('episodes', [])]
        lines += details(f"Episodes of {entry.get('label') or entry.get('name')} ({len(rows)})",
                         table(header, rows))
    return lines


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
    return [s for s in (final_set(run, 'heldout'), final_set(run, 'train')) if s]


def pick_examples(run: Run) -> tuple[Any, Any]:
    """Pick a successful and a failed (path, trace) pair of the final DQN, each or None.

    The failure is the diagnosed episode when its trace exists (the early checkpoint's when the
    final model never failed), else the first failure.
    """
    traces = [t for s in dqn_sets_for_examples(run) for t in load_traces(run, s['name'])]
    success = next((t for t in traces if t[1].get('outcome') == 'success'), None)
    diagnosis = run.diagnosis or {}
    failures = [t for t in traces if t[1].get('outcome') != 'success']
    failed = next((t for t in failures if t[1].get('set') == diagnosis.get('set')
                   and t[1].get('seed') == diagnosis.get('seed')), None)
    if failed is None and not failures and diagnosis.get('set'):
        # the final model failed nowhere: the diagnosed failure is the early checkpoint's
        failed = next((t for t in load_traces(run, diagnosis['set'])
                       if t[1].get('seed') == diagnosis.get('seed')), None)
    return success, failed or (failures[0] if failures else None)


def section_trajectories(run: Run) -> list[str]:
    """Build section 5: the trajectory grid, example paths and a contact sheet of frames."""
    arena = (run.results or {}).get('arena')
    sets = dqn_sets_for_examples(run)
    grid = [t for _, t in load_traces(run, sets[0]['name'])] if sets else []
    if not arena or not grid:
        return missing('traces of the final DQN under `eval/traces/`',
                       f'nav-eval-evaluate {run.shown}')
    name = sets[0].get('label') or sets[0]['name']
    out, ref = run.figure('trajectory_grid.png')
    plots.trajectory_grid(grid, arena, out, title=f'{name}: first {min(len(grid), 10)} episodes')
    lines = image(ref, f'{name}: top-down paths (orange-red: obstacles, green: goal with the '
                  'dashed success radius, blue arrow: start pose, ring: final pose)')
    success, failed = pick_examples(run)
    for kind, example in (('success', success), ('failure', failed)):
        if example is None:
            lines += [f'No {kind} among the traced final-DQN episodes.', '']
            continue
        trace = example[1]
        out, ref = run.figure(f'trajectory_{kind}.png')
        plots.trajectory(trace, arena, out)
        caption = (f"{kind.capitalize()}: {trace.get('set')} seed {trace.get('seed')} "
                   f"({trace.get('outcome')}, {len(trace.get('steps', []))} steps)")
        if str(trace.get('set', '')).startswith('early'):
            caption += ("; the final model failed in none of its episodes, so this is the early "
                        "checkpoint's failure")
        lines += image(ref, caption)
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
        return lines + image(ref, caption)
    return lines + missing('camera frames (`seed_<seed>_frames.npz`) of the shown episodes',
                           f'nav-eval-evaluate {run.shown}')


# --- rollout videos -----------------------------------------------------------------------------

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


def write_videos(run: Run, folder: Path) -> list[tuple[str, Path | None, str]]:
    """Write the video of every episode ``video_episodes`` lists into ``folder``.

    Returns (caption, video path or None, why not) per episode; older videos in ``folder``
    are removed.
    """
    arena = (run.results or {}).get('arena')
    episodes = video_episodes(run) if arena else []
    for stale in Path(folder).glob('*.mp4'):
        stale.unlink()
    written: list[tuple[str, Path | None, str]] = []
    for caption, path, trace in episodes:
        try:
            out = videos.write_trace_video(path, trace, arena, folder)
        except (OSError, RuntimeError, ValueError, KeyError) as exc:
            written.append((caption, None, f'{type(exc).__name__}: {exc}'))
            continue
        written.append((caption, out, '' if out else f'no frames beside `{path.name}`'))
    return written


def section_videos(run: Run) -> list[str]:
    """Link the rollout videos (``report/videos/``); Result.html embeds them as players."""
    try:
        written = write_videos(run, run.figures.parent / VIDEOS)
    except (OSError, ValueError, RuntimeError, ImportError) as exc:  # no encoder, bad traces
        # the rest of the section (the trajectories) stands without them
        return [f'> **Could not make the rollout videos:** {type(exc).__name__}: {exc}', '']
    if not written:
        return []
    lines = [f'**Rollout videos**: the policy observation (left) beside the top-down path so '
             f'far (right), one frame per decision at {videos.FPS} frames/s, labelled with the '
             'step, action, reward, return, distance and outcome.', '']
    for caption, out, problem in written:
        lines += video_link(f'{VIDEOS}/{out.name}', caption) if out else [
            f'{caption}: no video ({problem}).', '']
    return lines


def include_markdown(run: Run, source: Path, prefix: str) -> list[str]:
    """Return a Markdown file's lines verbatim; its relative images are copied to the report."""
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
    return [IMAGE_RE.sub(relink, source.read_text()).rstrip(), '']


def section_diagnosis(run: Run) -> list[str]:
    """Build section 6: the failure diagnosis with the evidence figures it names."""
    source = run.path / EVAL / DIAGNOSIS_TEXT
    diagnosis = run.diagnosis or {}
    if not source.is_file() and not diagnosis:
        return missing('a failure diagnosis (`eval/diagnosis.md`)',
                       f'nav-eval-diagnose {run.shown}')
    if source.is_file():
        lines = include_markdown(run, source, 'diagnosis')
    else:
        lines = [f"{diagnosis.get('summary', '')}", ''] + table(
            ['Layer', 'Status', 'Evidence'],
            [[layer.get('layer'), layer.get('status'), '; '.join(layer.get('evidence', []))]
             for layer in diagnosis.get('layers', [])])
    shown = '\n'.join(lines)
    for figure in diagnosis.get('figures', []):
        found = run.path / figure
        name = found.name if found.name.startswith('diagnosis') else f'diagnosis_{found.name}'
        if not found.is_file():
            lines += [f'> **Missing:** figure `{figure}` named by `eval/diagnosis.json`.', '']
        elif f'{FIGURES}/{name})' not in shown:
            out, ref = run.figure(name)
            shutil.copyfile(found, out)
            lines += image(ref, f'Diagnosis evidence: {figure}')
    return lines


def section_experiments(run: Run, experiments: Path | None) -> list[str]:
    """Build section 7: the experiments log included verbatim."""
    if experiments is None:
        return missing('the experiments log (attempts and targeted improvements)',
                       f'nav-eval-report {run.shown} --experiments docs/experiments.md')
    if not Path(experiments).is_file():
        return [f'> **Missing:** the experiments log `{experiments}` does not exist.', '']
    return include_markdown(run, Path(experiments), 'experiments')


def default_commands(run: Run, experiments: Path | None = None) -> list[str]:
    """Return the commands that reproduce the run, stage by stage (section 8)."""
    name = Path(run.shown).name
    log = f' --experiments {display_path(experiments)}' if experiments else ''
    return [f'nav-gym-validate --json {run.shown}/validation.json',
            f'nav-gym-train --config {run.shown}/config.yaml --run-name {name}_again',
            f'nav-eval-evaluate {run.shown}',
            f'nav-eval-diagnose {run.shown}',
            f'nav-eval-report {run.shown}{log}',
            '# or every stage in one command (ros2 run equivalents: nav_gym train, ...):',
            f'visnav-pipeline --config {run.shown}/config.yaml --run-name {name}_again']


def evidence(run: Run, experiments: Path | None) -> list[str]:
    """Build the workshop's evidence checklist, with where each item is and whether it is there."""
    names = ' '.join(str(c.get('name')) for c in run.validation or [])
    diagnosed = (run.path / EVAL / DIAGNOSIS_TEXT).is_file() or bool(run.diagnosis)
    items = [('Observation shape, dtype, min/max checks', 1, 'Observation' in names),
             ('Action-space verification', 1, 'Action space' in names),
             ('`check_env()` result', 1, 'check_env' in names),
             ('Training curves (return, length)', 2, (run.path / MONITOR).is_file()),
             ('Training wall-clock time and information', 2, bool(run.summary)),
             ('Early and final checkpoint comparison', 3,
              any(str(s.get('name')).startswith('early_') for s in run.sets())),
             ('Evaluation table: random, DQN train, DQN held-out', 4,
              bool(final_set(run, 'train') and final_set(run, 'heldout'))),
             ('Representative trajectories', 5, bool(dqn_sets_for_examples(run))),
             ('One failed DQN episode with a diagnosis', 6, diagnosed),
             ('One targeted improvement and justification', 7,
              bool(experiments and Path(experiments).is_file()))]
    return table(['Evidence', 'Section', 'Status'],
                 [[what, SECTIONS[n - 1], 'present' if ok else '**MISSING**']
                  for what, n, ok in items])


def build_markdown(run: Run, experiments: Path | None, commands: list[str] | None) -> str:
    """Return the report's Markdown: header, evidence checklist and every section.

    A section whose input is malformed says so instead of failing the report.
    """
    bodies = (section_checks, section_training, section_early,
              lambda r: section_evaluation(r) + section_closed_loop(r.closed_loop, r.shown),
              lambda r: section_trajectories(r) + section_videos(r), section_diagnosis,
              lambda r: section_experiments(r, experiments),
              lambda r: ['```bash', *(commands or default_commands(r, experiments)), '```', ''])
    sections: list[str] = []
    for title, body in zip(SECTIONS, bodies, strict=True):
        try:
            lines = body(run)
        except (OSError, ValueError, KeyError, IndexError, TypeError) as exc:  # malformed input
            lines = [f'> **Could not build this section:** {type(exc).__name__}: {exc}', '']
        sections += [f'## {title}', '', *lines]
    header = [f'# Result: {Path(run.shown).name}', '',
              f'Run directory `{run.shown}`; report written {datetime.now():%Y-%m-%d %H:%M} by '
              '`nav-eval-report`.', '', *evidence(run, experiments)]
    for problem in run.problems:
        header += [f'> **Unreadable input:** {problem}', '']
    return '\n'.join(header + sections).rstrip() + '\n'


def write_report(run_dir: Path, experiments: Path | None = None,
                 commands: list[str] | None = None) -> Path:
    """Write RUN/report/Result.md, Result.html and figures/; returns the Markdown path."""
    run = load_run(run_dir)
    if run.figures.is_dir():
        for stale in run.figures.glob('*.png'):
            stale.unlink()
    run.figures.mkdir(parents=True, exist_ok=True)
    text = build_markdown(run, experiments, commands)
    report = run.figures.parent / REPORT_TEXT
    report.write_text(text)
    report.with_suffix('.html').write_text(to_html(text, report.parent, run.shown))
    return report
