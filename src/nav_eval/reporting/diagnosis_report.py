"""Diagnose an evaluated episode and write the evidence: ``eval/diagnosis.{json,md}``, figures.

:func:`diagnose_run` picks the episode (:mod:`nav_eval.evaluation.selection`), re-runs it for the
determinism check, runs the layer checks (:mod:`nav_eval.analysis.diagnosis`) and writes the
Markdown, JSON and figures (matplotlib) that ``nav-eval-diagnose`` and the report show.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.analysis.diagnosis import diagnose, training_evidence
from nav_eval.evaluation.runner import rerun
from nav_eval.evaluation.selection import load_episode, pick_episode
from nav_eval.evaluation.sets import run_config
from nav_eval.reporting import plots
from nav_gym.env.actions import ACTION_NAMES, action_label
from nav_gym.policy.servo import goal_bearing
from nav_gym.training.run_dir import (
    DIAGNOSIS,
    DIAGNOSIS_TEXT,
    EVAL,
    FIGURES,
    RESULTS,
    eval_settings,
)
from nav_sim.core.config import SimConfig


def step_table(trace: dict, frames: np.ndarray) -> str:
    """Markdown table: one row per step with action, reward terms, distance, Q-values."""
    rows = ['| step | action | goal in view (bearing) | progress | goal | collision | reward '
            '| distance | Q(left, fwd, right) | event |', '|---:|---|---|---:|---:|---:|---:|'
            '---:|---|---|']
    for i, s in enumerate(trace['steps']):
        bearing = goal_bearing(frames[i])
        t = s['reward_terms']
        q = ', '.join(f'{v:+.2f}' for v in s['q_values']) if s.get('q_values') else '-'
        rows.append(f"| {s['step']} | {s['action']} {s['action_name']} | "
                    f"{'no' if bearing is None else f'{bearing:+.2f}'} | "
                    f"{t['progress']:+.4f} | {t['goal']:g} | {t['collision']:g} | "
                    f"{s['reward']:+.4f} | {s['distance']:.3f} | {q} | {s['event']} |")
    return '\n'.join(rows)


def trace_figure(trace: dict, frames: np.ndarray, out: Path) -> Path:
    """Distance, cumulative reward, Q-values and goal bearing against the step."""
    import matplotlib.pyplot as plt
    steps = trace['steps']
    x = [s['step'] for s in steps]
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    axes[0].plot([0, *x], [trace['scenario']['initial_distance'],
                           *[s['distance'] for s in steps]], color='k')
    axes[0].set_ylabel('distance to goal (m)')
    axes[0].plot(x, np.cumsum([s['reward'] for s in steps]), color='tab:blue')
    axes[0].legend(['distance (m)', 'cumulative reward'], loc='upper right')
    q = [s['q_values'] for s in steps]
    actions = [s['action'] for s in steps]
    if all(q):
        for k, name in enumerate(ACTION_NAMES):
            axes[1].plot(x, [v[k] for v in q], label=f'Q({name})', lw=1)
        axes[1].scatter(x, [v[a] for v, a in zip(q, actions, strict=True)], s=8, c='k',
                        label='chosen', zorder=3)
        axes[1].set_ylabel('Q-values')
    else:
        axes[1].step(x, actions, where='mid', color='k', label='action')
        axes[1].set_yticks([0, 1, 2], ACTION_NAMES)
    axes[1].legend(loc='upper right', fontsize=8)
    bearings = [goal_bearing(frames[i]) for i in range(len(steps))]
    axes[2].plot(x, [math.nan if b is None else b for b in bearings], '.', color='tab:green')
    axes[2].axhline(0, color='grey', lw=0.5)
    axes[2].set_ylim(-1.05, 1.05)
    axes[2].set_ylabel('goal bearing in image\n(-1 left .. +1 right)')
    axes[2].set_xlabel('step')
    fig.suptitle(f"{trace['set']} seed {trace['seed']}: {trace['outcome']}")
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def write_diagnosis(run_dir: Path, diagnosis: dict, trace: dict, frames: np.ndarray) -> Path:
    """Write diagnosis.json, diagnosis.md and figures under RUN_DIR/eval; return the .md path.

    The figures (relative to the run directory) are added to ``diagnosis``.
    """
    eval_dir = run_dir / EVAL
    fig_dir = eval_dir / FIGURES
    fig_dir.mkdir(parents=True, exist_ok=True)
    stem = f"diagnosis_{trace['set']}_seed_{trace['seed']}"
    labels = ['reset'] + [f"{s['step']} {action_label(s['action_name'])}" for s in trace['steps']]
    figures = [trace_figure(trace, frames, fig_dir / f'{stem}_trace.png'),
               plots.contact_sheet(frames, fig_dir / f'{stem}_frames.png', labels=labels)]
    diagnosis['figures'] = [str(f.relative_to(run_dir)) for f in figures]
    (eval_dir / DIAGNOSIS).write_text(json.dumps(diagnosis, indent=1))
    lines = [f"**Episode:** set `{trace['set']}`, seed {trace['seed']} ({trace['split']}), "
             f"checkpoint `{trace.get('checkpoint')}`, outcome **{trace['outcome']}** after "
             f"{len(trace['steps'])} steps.", '', f"**Verdict:** {diagnosis['summary']}", '',
             '| layer | status | evidence |', '|---|---|---|']
    for v in diagnosis['layers']:
        lines.append(f"| {v['layer']} | {v['status']} | {'<br>'.join(v['evidence'])} |")
    lines += ['', *[f'![{f.stem}]({f.relative_to(eval_dir)})' for f in figures], '',
              '<details><summary>Every step</summary>', '', step_table(trace, frames), '',
              '</details>', '']
    md = eval_dir / DIAGNOSIS_TEXT
    md.write_text('\n'.join(lines))
    return md


def diagnose_run(run_dir: Path, set_name: str | None = None, seed: int | None = None,
                 replay: bool = True) -> dict[str, Any]:
    """Diagnose an episode of a run's evaluation and write the evidence."""
    eval_dir = run_dir / EVAL
    set_name, seed = pick_episode(eval_dir, set_name, seed)
    trace, frames = load_episode(eval_dir, set_name, seed)
    config = run_config(run_dir)
    env = config.env_config()
    sim = SimConfig.from_params(config.sim_params)
    results = json.loads((eval_dir / RESULTS).read_text())
    diagnosis = diagnose(trace, frames, sim, env,
                         training_evidence(run_dir, config.exploration_final_eps),
                         results.get('config'), eval_settings(config),
                         rerun(run_dir, trace) if replay else None)
    md = write_diagnosis(run_dir, diagnosis, trace, frames)
    print(diagnosis['summary'])
    for v in diagnosis['layers']:
        print(f"  {v['layer']:<24} {v['status']:<8} {'; '.join(v['evidence'])}")
    print(f'evidence: {md}')
    return diagnosis
