"""A run's result report: its sections as text, and Result.md/Result.html written from them.

Reads what the other commands left in RUN_DIR (validation.json, summary.json, monitor.csv,
checkpoints/, eval/results.json, eval/traces/, eval/diagnosis.*, eval_closed_loop/results.json)
and writes RUN_DIR/report/Result.md and Result.html.  :func:`write_report` first has the
figures drawn into RUN_DIR/report/figures/ (:mod:`nav_eval.reporting.run_figures`) and the
rollout videos encoded into RUN_DIR/report/videos/ (:mod:`nav_eval.reporting.videos`); the
sections then only build text from what was made.  Every section is written; one whose input
is missing says which command produces it.
"""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.reporting import plots, videos
from nav_eval.reporting.closed_loop import section_closed_loop
from nav_eval.reporting.format import (
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
from nav_eval.reporting.run_figures import MALFORMED, Figures, draw_figures
from nav_eval.reporting.run_inputs import Run, dqn_sets_for_examples, final_set, load_run
from nav_eval.reporting.videos import Clips, write_run_videos
from nav_gym.training.run_dir import (
    DIAGNOSIS_TEXT,
    EVAL,
    FINAL_MODEL,
    MONITOR,
    REPORT_TEXT,
    VIDEOS,
    parse_checkpoint_name,
    run_settings,
)
from nav_gym.training.spec import LEGACY_DEFAULTS, learner_of
from nav_sim.core.config import HELDOUT, TRAIN

SECTIONS = ('1. Observation and action checks', '2. Training',
            '3. Early vs final checkpoint comparison', '4. Evaluation',
            '5. Representative trajectories', '6. Failure diagnosis',
            '7. Attempts and targeted improvements', '8. Reproduce')
HYPERPARAMETERS = ('double_q', 'n_steps', 'dueling', 'augment_shift', 'augment_colour',
                   'prioritized_replay', 'frame_stack', 'previous_action', 'aux_depth',
                   'munchausen', 'reset_interval', 'recurrent', 'priority_alpha', 'priority_beta',
                   'learning_rate', 'buffer_size', 'learning_starts', 'batch_size', 'gamma',
                   'train_freq', 'gradient_steps', 'target_update_interval',
                   'exploration_fraction', 'exploration_initial_eps', 'exploration_final_eps',
                   'seed', 'n_envs', 'split', 'max_episode_steps', 'forward_speed', 'turn_rate',
                   'turn_speed', 'sim_params')
EVAL_COLUMNS = ('Set', 'Policy', 'Split', 'Episodes', 'Success rate', 'Collision rate',
                'Timeout rate', 'Mean length', 'Mean SPL', 'Mean return')


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


def section_training(run: Run, figures: Figures) -> list[str]:
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
    if figures.training_curves is None:
        return lines + missing('`monitor.csv` (episode returns and lengths)', 'nav-gym-train')
    data = plots.monitor_arrays(run.path / MONITOR)
    ref = figures.training_curves
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
                                                   and s.get('split') == TRAIN]),
              ('final DQN on training seeds', final_set(run, TRAIN)),
              ('final DQN on held-out seeds', final_set(run, HELDOUT))]
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


def section_trajectories(run: Run, figures: Figures) -> list[str]:
    """Build section 5: the trajectory grid, example paths and a contact sheet of frames."""
    if figures.grid is None:
        return missing('traces of the final DQN under `eval/traces/`',
                       f'nav-eval-evaluate {run.shown}')
    ref, name = figures.grid
    lines = image(ref, f'{name}: top-down paths (orange-red: obstacles, green: goal with the '
                  'dashed success radius, blue arrow: start pose, ring: final pose)')
    for kind, example in figures.examples.items():
        if example is None:
            lines += [f'No {kind} among the traced final-DQN episodes.', '']
            continue
        trace = example.trace
        caption = (f"{kind.capitalize()}: {trace.get('set')} seed {trace.get('seed')} "
                   f"({trace.get('outcome')}, {len(trace.get('steps', []))} steps)")
        if str(trace.get('set', '')).startswith('early'):
            caption += ("; the final model failed in none of its episodes, so this is the early "
                        "checkpoint's failure")
        lines += image(example.ref, caption)
    if figures.contact_sheet is not None:
        return lines + image(*figures.contact_sheet)
    return lines + missing('camera frames (`seed_<seed>_frames.npz`) of the shown episodes',
                           f'nav-eval-evaluate {run.shown}')


def section_videos(clips: Clips) -> list[str]:
    """Link the rollout videos (``report/videos/``); Result.html embeds them as players."""
    if isinstance(clips, str):  # no encoder, bad traces: the trajectories stand without them
        return [f'> **Could not make the rollout videos:** {clips}', '']
    if not clips:
        return []
    lines = [f'**Rollout videos**: the policy observation (left) beside the top-down path so '
             f'far (right), one frame per decision at {videos.FPS} frames/s, labelled with the '
             'step, action, reward, return, distance and outcome.', '']
    for caption, out, problem in clips:
        lines += video_link(f'{VIDEOS}/{out.name}', caption) if out else [
            f'{caption}: no video ({problem}).', '']
    return lines


def section_diagnosis(run: Run, figures: Figures) -> list[str]:
    """Build section 6: the failure diagnosis with the evidence figures it names."""
    source = run.path / EVAL / DIAGNOSIS_TEXT
    diagnosis = run.diagnosis or {}
    if not source.is_file() and not diagnosis:
        return missing('a failure diagnosis (`eval/diagnosis.md`)',
                       f'nav-eval-diagnose {run.shown}')
    if source.is_file():
        lines = list(figures.included[source])
    else:
        lines = [f"{diagnosis.get('summary', '')}", ''] + table(
            ['Layer', 'Status', 'Evidence'],
            [[layer.get('layer'), layer.get('status'), '; '.join(layer.get('evidence', []))]
             for layer in diagnosis.get('layers', [])])
    for figure, ref in figures.diagnosis_figures:
        lines += (image(ref, f'Diagnosis evidence: {figure}') if ref else
                  [f'> **Missing:** figure `{figure}` named by `eval/diagnosis.json`.', ''])
    return lines


def section_experiments(run: Run, experiments: Path | None, figures: Figures) -> list[str]:
    """Build section 7: the experiments log included verbatim."""
    if experiments is None:
        return missing('the experiments log (attempts and targeted improvements)',
                       f'nav-eval-report {run.shown} --experiments docs/experiments.md')
    if not Path(experiments).is_file():
        return [f'> **Missing:** the experiments log `{experiments}` does not exist.', '']
    return list(figures.included[Path(experiments)])


def default_commands(run: Run, experiments: Path | None = None) -> list[str]:
    """Return the commands that reproduce the run, stage by stage (section 8)."""
    name = Path(run.shown).name
    log = f' --experiments {display_path(experiments)}' if experiments else ''
    # a config saved before a setting existed: its value then, which today's default is not
    then = ''.join(f" --{key.replace('_', '-')} {str(value).lower()}"
                   for key, value in LEGACY_DEFAULTS.items() if key not in (run.config or {}))
    return [f'nav-gym-validate --json {run.shown}/validation.json',
            f'nav-gym-train --config {run.shown}/config.yaml{then} --run-name {name}_again',
            f'nav-eval-evaluate {run.shown}',
            f'nav-eval-diagnose {run.shown}',
            f'nav-eval-report {run.shown}{log}',
            '# or every stage in one command (ros2 run equivalents: nav_gym train, ...):',
            f'visnav-pipeline --config {run.shown}/config.yaml{then} --run-name {name}_again']


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
              bool(final_set(run, TRAIN) and final_set(run, HELDOUT))),
             ('Representative trajectories', 5, bool(dqn_sets_for_examples(run))),
             ('One failed DQN episode with a diagnosis', 6, diagnosed),
             ('One targeted improvement and justification', 7,
              bool(experiments and Path(experiments).is_file()))]
    return table(['Evidence', 'Section', 'Status'],
                 [[what, SECTIONS[n - 1], 'present' if ok else '**MISSING**']
                  for what, n, ok in items])


def build_markdown(run: Run, experiments: Path | None, commands: list[str] | None,
                   figures: Figures | None = None, clips: Clips = ()) -> str:
    """Return the report's Markdown: header, evidence checklist and every section.

    ``figures`` and ``clips`` are what was drawn and encoded before (none: the sections say
    their figures are missing).  A section whose input is malformed says so instead of
    failing the report.
    """
    figures = figures or Figures()
    bodies = (section_checks, lambda r: section_training(r, figures), section_early,
              lambda r: section_evaluation(r) + section_closed_loop(r.closed_loop, r.shown),
              lambda r: section_trajectories(r, figures) + section_videos(clips),
              lambda r: section_diagnosis(r, figures),
              lambda r: section_experiments(r, experiments, figures),
              lambda r: ['```bash', *(commands or default_commands(r, experiments)), '```', ''])
    sections: list[str] = []
    for number, (title, body) in enumerate(zip(SECTIONS, bodies, strict=True), start=1):
        try:
            if number in figures.errors:
                raise _FigureError(figures.errors[number])
            lines = body(run)
        except MALFORMED as exc:  # malformed input
            lines = [f'> **Could not build this section:** {_problem(exc)}', '']
        sections += [f'## {title}', '', *lines]
    header = [f'# Result: {Path(run.shown).name}', '',
              f'Run directory `{run.shown}`; report written {datetime.now():%Y-%m-%d %H:%M} by '
              '`nav-eval-report`.', '', *evidence(run, experiments)]
    for problem in run.problems:
        header += [f'> **Unreadable input:** {problem}', '']
    return '\n'.join(header + sections).rstrip() + '\n'


def _problem(exc: Exception) -> str:
    """Say what went wrong: a figure's error as it was kept, else the exception's type and text."""
    return str(exc) if isinstance(exc, _FigureError) else f'{type(exc).__name__}: {exc}'


class _FigureError(ValueError):
    """A section's figures failed to draw (the message is the error as it was kept)."""


def write_report(run_dir: Path, experiments: Path | None = None,
                 commands: list[str] | None = None) -> Path:
    """Write RUN/report/Result.md, Result.html, figures/ and videos/; returns the Markdown path.

    The figures and the videos are made first; the text is built from what they made.
    """
    run = load_run(run_dir)
    if run.figures.is_dir():
        for stale in run.figures.glob('*.png'):
            stale.unlink()
    run.figures.mkdir(parents=True, exist_ok=True)
    figures = draw_figures(run, experiments)
    try:
        clips: Clips = write_run_videos(run, run.figures.parent / VIDEOS)
    except (OSError, ValueError, RuntimeError, ImportError) as exc:  # no encoder, bad traces
        clips = f'{type(exc).__name__}: {exc}'
    text = build_markdown(run, experiments, commands, figures, clips)
    report = run.figures.parent / REPORT_TEXT
    report.write_text(text)
    report.with_suffix('.html').write_text(to_html(text, report.parent, run.shown))
    return report
