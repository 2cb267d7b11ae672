"""Diagnose one failed evaluation episode layer by layer (the workshop's failure-layer model).

    ros2 run nav_eval diagnose RUN_DIR [--set dqn_heldout] [--seed N] [--no-rerun]

Reads the episode's trace and frames written by ``nav_eval evaluate`` (default: the first
failed episode of ``dqn_heldout``, else of ``dqn_train``), shows frames, actions, reward terms,
distance and Q-values per step, checks each layer's evidence (see ``nav_eval.layers``),
re-runs the episode to test that evaluation is deterministic, and names the earliest layer that
looks broken or suspect.  Writes ``RUN_DIR/eval/diagnosis.{json,md}`` and its figures.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval import layers
from nav_eval.errors import DiagnosisError
from nav_gym import run_dir as layout
from nav_gym.actions import ACTION_NAMES, action_label
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.config import EnvConfig
from nav_gym.timing import quiet_learner_threads
from nav_sim.config import SimConfig

# the final model's failures first; if it fails nowhere, the early checkpoint's
SEARCH_ORDER = ('dqn_heldout', 'dqn_train', 'early_heldout', 'early_train')


def pick_episode(eval_dir: Path, set_name: str | None, seed: int | None) -> tuple[str, int]:
    """Return the (set, seed) to diagnose: as given, or the first failure in ``SEARCH_ORDER``."""
    results_path = eval_dir / layout.RESULTS
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
            if (seed is None and e['outcome'] != 'success') or e['seed'] == seed:
                return name, e['seed']
    if seed is not None:
        raise DiagnosisError(f'seed {seed} is not in set(s) {names}')
    raise DiagnosisError(f'no failed episode in {names}: nothing to diagnose')


def training_evidence(run_dir: Path, final_eps: float, tail: int = 50) -> dict | None:
    """Episodes and late success rate from the run's Monitor CSV."""
    path = run_dir / layout.MONITOR
    if not path.is_file():
        return None
    success = layout.read_monitor(path).get('is_success', [])
    if not success:
        return None
    last = success[-tail:]
    return {'episodes': len(success), 'tail': len(last),
            'tail_success': sum(map(layout.truthy, last)) / len(last), 'final_eps': final_eps}


def rerun(run_dir: Path, trace: dict) -> list[int]:
    """Replay the episode's seed with the same policy; returns the actions it took."""
    from nav_eval.evaluate import env_for_run, make_policy, run_config, run_episode
    config = run_config(run_dir)
    policy = make_policy(trace['policy'], run_dir, trace['checkpoint'])
    env = env_for_run(config, record=False)
    try:
        _, replay, _ = run_episode(env, policy, trace['seed'], trace['split'])
    finally:
        env.close()
    return [s['action'] for s in replay['steps']]


def diagnose(trace: dict, frames: np.ndarray, sim: SimConfig, env: EnvConfig,
             training: dict | None = None, eval_config: dict | None = None,
             run_config: dict | None = None,
             rerun_actions: list[int] | None = None) -> dict[str, Any]:
    """Run every layer check; returns the diagnosis (JSON-ready)."""
    steps, scenario = trace['steps'], trace['scenario']
    weights = {k: getattr(env, k) for k in ('progress_weight', 'step_penalty', 'goal_reward',
                                            'collision_penalty')}
    verdicts = [
        layers.check_observations(frames, steps),
        layers.check_actions(steps, scenario['start'], env.forward_speed * sim.ctrl_dt,
                             env.turn_rate * sim.ctrl_dt,
                             layers.arc_chord(env.turn_speed, env.turn_rate, sim.ctrl_dt)),
        layers.check_reward(steps, scenario['initial_distance'], weights),
        layers.check_policy(steps, frames, trace['outcome'], training,
                            layers.centre_band(env.turn_rate * sim.ctrl_dt,
                                               math.radians(sim.camera_hfov_deg))),
        layers.check_evaluation(trace, eval_config, run_config, rerun_actions),
    ]
    earliest = next((v for v in verdicts if v.status in ('broken', 'suspect')), None)
    summary = (f"{trace['set']} seed {trace['seed']} ended in {trace['outcome']} after "
               f"{len(steps)} steps. ")
    if earliest is None:
        summary += 'No layer shows a problem in the evidence available.'
    else:
        summary += (f'Earliest layer that looks {earliest.status}: {earliest.layer} — '
                    f'{earliest.reason}')
    return {'set': trace['set'], 'seed': trace['seed'], 'split': trace['split'],
            'checkpoint': trace.get('checkpoint'), 'outcome': trace['outcome'],
            'earliest_suspect_layer': earliest.layer if earliest else None,
            'layers': [asdict(v) for v in verdicts], 'summary': summary}


def step_table(trace: dict, frames: np.ndarray) -> str:
    """Markdown table: one row per step with action, reward terms, distance, Q-values."""
    rows = ['| step | action | goal in view (bearing) | progress | goal | collision | reward '
            '| distance | Q(left, fwd, right) | event |', '|---:|---|---|---:|---:|---:|---:|'
            '---:|---|---|']
    for i, s in enumerate(trace['steps']):
        bearing = layers.goal_bearing(frames[i])
        t = s['reward_terms']
        q = ', '.join(f'{v:+.2f}' for v in s['q_values']) if s.get('q_values') else '-'
        rows.append(f"| {s['step']} | {s['action']} {s['action_name']} | "
                    f"{'no' if bearing is None else f'{bearing:+.2f}'} | "
                    f"{t['progress']:+.4f} | {t['goal']:g} | {t['collision']:g} | "
                    f"{s['reward']:+.4f} | {s['distance']:.3f} | {q} | {s['event']} |")
    return '\n'.join(rows)


def trace_figure(trace: dict, frames: np.ndarray, out: Path) -> Path:
    """Distance, cumulative reward, Q-values and goal bearing against the step."""
    import matplotlib
    matplotlib.use('Agg')
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
    bearings = [layers.goal_bearing(frames[i]) for i in range(len(steps))]
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
    from nav_eval import plots
    eval_dir = run_dir / layout.EVAL
    fig_dir = eval_dir / 'figures'
    fig_dir.mkdir(parents=True, exist_ok=True)
    stem = f"diagnosis_{trace['set']}_seed_{trace['seed']}"
    labels = ['reset'] + [f"{s['step']} {action_label(s['action_name'])}" for s in trace['steps']]
    figures = [trace_figure(trace, frames, fig_dir / f'{stem}_trace.png'),
               plots.contact_sheet(frames, fig_dir / f'{stem}_frames.png', labels=labels)]
    diagnosis['figures'] = [str(f.relative_to(run_dir)) for f in figures]
    (eval_dir / 'diagnosis.json').write_text(json.dumps(diagnosis, indent=1))
    lines = [f"**Episode:** set `{trace['set']}`, seed {trace['seed']} ({trace['split']}), "
             f"checkpoint `{trace.get('checkpoint')}`, outcome **{trace['outcome']}** after "
             f"{len(trace['steps'])} steps.", '', f"**Verdict:** {diagnosis['summary']}", '',
             '| layer | status | evidence |', '|---|---|---|']
    for v in diagnosis['layers']:
        lines.append(f"| {v['layer']} | {v['status']} | {'<br>'.join(v['evidence'])} |")
    lines += ['', *[f'![{f.stem}]({f.relative_to(eval_dir)})' for f in figures], '',
              '<details><summary>Every step</summary>', '', step_table(trace, frames), '',
              '</details>', '']
    md = eval_dir / 'diagnosis.md'
    md.write_text('\n'.join(lines))
    return md


def load_episode(eval_dir: Path, set_name: str, seed: int) -> tuple[dict, np.ndarray]:
    """Return the trace and the observations of one evaluated episode."""
    trace_path = layout.trace_path(eval_dir, set_name, seed)
    frames_path = layout.frames_path(trace_path)
    if not (trace_path.is_file() and frames_path.is_file()):
        raise DiagnosisError(f'no trace for {set_name} seed {seed} in '
                             f'{eval_dir / layout.TRACES}; re-run the evaluation')
    with np.load(frames_path) as data:
        frames = data['obs']
    return json.loads(trace_path.read_text()), frames


def run(run_dir: Path, set_name: str | None = None, seed: int | None = None,
        replay: bool = True) -> dict[str, Any]:
    """Diagnose an episode of a run's evaluation and write the evidence."""
    from nav_eval.evaluate import run_config
    eval_dir = run_dir / layout.EVAL
    set_name, seed = pick_episode(eval_dir, set_name, seed)
    trace, frames = load_episode(eval_dir, set_name, seed)
    config = run_config(run_dir)
    env = config.env_config()
    sim = SimConfig.from_params(config.sim_params)
    results = json.loads((eval_dir / layout.RESULTS).read_text())
    diagnosis = diagnose(trace, frames, sim, env,
                         training_evidence(run_dir, config.exploration_final_eps),
                         results.get('config'), layout.eval_settings(config),
                         rerun(run_dir, trace) if replay else None)
    md = write_diagnosis(run_dir, diagnosis, trace, frames)
    print(diagnosis['summary'])
    for v in diagnosis['layers']:
        print(f"  {v['layer']:<24} {v['status']:<8} {'; '.join(v['evidence'])}")
    print(f'evidence: {md}')
    return diagnosis


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-eval-diagnose`` command."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('run_dir', type=Path, help='training run directory (evaluated)')
    parser.add_argument('--set', dest='set_name', help='evaluation set (default: the first '
                        'failure of dqn_heldout, then dqn_train)')
    parser.add_argument('--seed', type=int, help='episode seed within the set')
    parser.add_argument('--no-rerun', action='store_true',
                        help='skip the determinism re-run of the episode')
    args = parser.parse_args(strip_ros_args(argv))
    quiet_learner_threads()  # the re-run's forward passes must not spin against the sim
    run_command('nav-eval-diagnose',
                lambda: run(args.run_dir, args.set_name, args.seed, not args.no_rerun) and 0)


if __name__ == '__main__':
    main()
