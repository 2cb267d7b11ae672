"""Play evaluation episodes through a run's own environment and write what they did.

The environment is built from the run's ``config.yaml`` (sim settings, action speeds, episode
limit), so preprocessing and action timing are those of training; the DQN acts with
``predict(deterministic=True)``.  An evaluation writes, under its output folder (``RUN/eval``
by default): ``results.json``, ``results.md``, ``episodes.csv``, per-episode traces
(``traces/<set>/seed_<n>.json`` + ``_frames.npz``) and, when recording, one rosbag2/MCAP bag per
set under ``bags/<set>/``.  The same evaluation twice gives identical files.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.analysis import metrics
from nav_eval.analysis.anatomy import goal_in_view
from nav_eval.errors import EvaluationError
from nav_eval.evaluation.policies import DQNPolicy, ExploringDQNPolicy, RandomPolicy
from nav_eval.evaluation.sets import EvalSet, run_config
from nav_eval.seeds import seed_range
from nav_gym.env.navigation import NavigationEnv
from nav_gym.errors import TrainConfigError
from nav_gym.policy.actors import Actor
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import (
    BAGS,
    EPISODES_CSV,
    EVAL,
    RESULTS,
    RESULTS_TABLE,
    eval_settings,
    frames_path,
    trace_path,
)
from nav_sim import interface
from nav_sim.core.config import TRAIN
from nav_sim.core.events import EVENT_NONE
from nav_sim.core.world import load_arena

#: where the sim was when the episode started (not part of the scenario; the bag has them)
SIM_COUNTERS = ('episode', 'period', 'stamp_ns')
WARM_UP_WAIT_S = 0.5  # how long a warm-up period may take to reach the recorder


def run_episode(env: NavigationEnv, policy: Actor, seed: int, split: str,
                recorder: Any = None) -> tuple[metrics.EpisodeResult, dict, np.ndarray]:
    """One episode: returns its result, its per-step trace and its observations."""
    obs, info = env.reset(seed=seed, options={'split': split})
    if recorder is not None:
        _recorded(recorder, env.last_stamp_ns)
    policy.begin_episode(seed)
    # a privileged baseline (the oracle) follows the true state; no other policy sees it
    follow = getattr(policy, 'follow', None)
    if follow is not None:
        follow(info)
    frames, steps = [obs], []
    total, truncated, event = 0.0, False, EVENT_NONE
    step_info: dict[str, Any] = {'distance': info['distance'], 'path_length': 0.0}
    while True:
        seen = goal_in_view(obs)  # what this decision saw, for the failure anatomy
        action, q_values = policy.act(obs)
        env.note_q_values(q_values)  # for the live view and the bag's /visnav/step
        obs, reward, terminated, truncated, step_info = env.step(action)
        if follow is not None:
            follow(step_info)
        if recorder is not None:
            _recorded(recorder, env.last_stamp_ns)
        frames.append(obs)
        total += reward
        event = step_info['event']
        steps.append({'step': step_info['step'], 'action': action,
                      'action_name': step_info['action_name'], 'reward': round(reward, 6),
                      'reward_terms': {k: round(v, 6) for k, v in
                                       step_info['reward_terms'].items()},
                      'distance': round(step_info['distance'], 6),
                      'pose': [round(v, 6) for v in step_info['pose']], 'event': event,
                      'q_values': q_values, 'goal_in_view': seen})
        if terminated or truncated:
            break
    result = metrics.episode_result(
        seed, split, event, truncated, len(steps), total, info['scenario']['initial_distance'],
        step_info['distance'], step_info['path_length'])
    scenario = {k: v for k, v in info['scenario'].items() if k not in SIM_COUNTERS}
    trace = {'seed': seed, 'split': split, 'outcome': result.outcome,
             'scenario': scenario, 'steps': steps}
    return result, trace, np.stack(frames)


def _recorded(recorder: Any, stamp_ns: int, timeout: float = 5.0) -> None:
    """Wait until the period's messages stamped ``stamp_ns`` are in the bag (lockstep).

    The sim publishes with depth 1, so the next command must wait for the recorder; a loss is
    reported, never silent.
    """
    from nav_eval.recording.bags import PERIOD_TOPICS
    if not recorder.wait_for(stamp_ns, timeout, PERIOD_TOPICS):
        print(f'warning: the bag misses messages of the period stamped {stamp_ns} ns',
              flush=True)


def arena_description(sim_params: dict[str, Any]) -> dict[str, Any]:
    """Arena geometry for top-down plots (loads the MJCF; renders nothing).

    ``walls`` are the interior walls (centre x, y and half extents), e.g. between rooms.
    """
    geometry, config = load_arena(sim_params)
    return {'world': config.world, 'half_size': geometry.half_size,
            'robot_radius': geometry.robot_radius,
            'walls': [[w[0], w[1], w[3], w[4]] for w in geometry.interior_walls],
            'goal_radius': config.goal_radius, 'goal_marker_radius': config.goal_marker_radius,
            'shapes': [{'name': s.name, 'kind': s.kind, 'half_x': s.half_x, 'half_y': s.half_y}
                       for s in geometry.shapes]}


def make_policy(kind: str, run_dir: Path, checkpoint: str | None) -> Actor:
    """Return the policy of an evaluation set or trace (``sets.SET_POLICIES``' values)."""
    if kind == 'random':
        return RandomPolicy()
    if kind == 'explore':
        epsilon = run_config(run_dir).exploration_final_eps
        return ExploringDQNPolicy(run_dir / str(checkpoint), epsilon)
    return DQNPolicy(run_dir / str(checkpoint))


def evaluate_set(env: NavigationEnv, run_dir: Path, eval_set: EvalSet, out: Path,
                 record: bool) -> dict[str, Any]:
    """Run every seed of a set; write its traces (and bag); return its results entry."""
    policy = make_policy(eval_set.policy, run_dir, eval_set.checkpoint)
    epsilon = getattr(policy, 'epsilon', None)
    exploration = {} if epsilon is None else {'epsilon': epsilon}
    trace_path(out, eval_set.name, 0).parent.mkdir(parents=True, exist_ok=True)
    recorder = _open_recorder(out / BAGS / eval_set.name, env) if record else None
    scene_writer = None
    if recorder is not None:  # the live view's scene topics go into the bag too
        from nav_eval.recording.scene import BagSceneWriter
        scene_writer = BagSceneWriter(recorder, env.config.sim_params)
        env.observers.append(scene_writer)
    results = []
    meta = {'set': eval_set.name, 'policy': eval_set.policy,
            'checkpoint': eval_set.checkpoint, **exploration}
    try:
        for seed in eval_set.seeds:
            result, trace, frames = run_episode(env, policy, seed, eval_set.split, recorder)
            results.append(result)
            write_episode(out, meta, result, trace, frames, recorder)
    finally:
        if scene_writer is not None:
            env.observers.remove(scene_writer)
        if recorder is not None:
            recorder.close()
    return set_entry(eval_set, results, **exploration)


def write_episode(out: Path, meta: dict[str, Any], result: metrics.EpisodeResult,
                  trace: dict[str, Any], frames: np.ndarray, recorder: Any = None) -> None:
    """Write an episode's trace and frames, annotate its bag and print its line.

    ``meta`` names the set (``set``, ``policy``, ``checkpoint``, ...); the trace goes to
    ``traces/<set>/seed_<n>.json`` under ``out``, its observations beside it.
    """
    trace = {**meta, **trace}
    trace_file = trace_path(out, meta['set'], result.seed)
    trace_file.parent.mkdir(parents=True, exist_ok=True)
    trace_file.write_text(json.dumps(trace, indent=1))
    np.savez_compressed(frames_path(trace_file), obs=frames)
    if recorder is not None:
        recorder.annotate({**meta, **result.to_dict()})
    print(f"  {meta['set']:<14} seed {result.seed:>4}: {result.outcome:<9} "
          f'{result.length:>4} steps  return {result.episode_return:+7.3f}  '
          f'SPL {result.spl:.3f}', flush=True)


def set_entry(eval_set: EvalSet, results: list[metrics.EpisodeResult],
              **extra: Any) -> dict[str, Any]:
    """Return a set's entry of ``results.json``: what ran, its summary and its episodes."""
    summary = metrics.summarize(results)
    return {'name': eval_set.name, 'label': eval_set.label, 'policy': eval_set.policy,
            'checkpoint': eval_set.checkpoint, **extra, 'split': eval_set.split,
            'seeds': list(eval_set.seeds), 'summary': summary.to_dict(),
            'episodes': [r.to_dict() for r in results]}


def open_recorder(path: Path, namespace: str, warm_up: Any, delivered: Any,
                  timeout: float = 10.0, **options: Any) -> Any:
    """Return a bag recorder on the sim in ``namespace`` that the sim is known to deliver to.

    The sim can match the recorder's subscriptions some time after the recorder has matched
    its publishers; what it publishes before then never reaches the bag.  So the recorder
    starts paused and ``warm_up()`` resets the sim (a warm-up period, not written; it returns
    the reset frame's stamp) until one whole control period has reached the recorder and
    ``delivered(recorder)`` says the commands reach it too; the bag starts after it.
    ``options`` go to the :class:`BagRecorder` (e.g. ``topics``).
    """
    from nav_eval.recording.bags import PERIOD_TOPICS, SIM_TOPICS
    from nav_eval.recording.recorder import BagRecorder
    if path.exists():
        shutil.rmtree(path)  # a re-run replaces the bag of the same set
    path.parent.mkdir(parents=True, exist_ok=True)
    # root names: the bag's topics are those of the live view and the Foxglove layout
    recorder = BagRecorder(path, namespace=namespace, paused=True, root_names=True, **options)
    deadline = time.monotonic() + timeout
    if recorder.wait_for_publishers(timeout, (*SIM_TOPICS, interface.CMD_VEL_TOPIC)):
        while time.monotonic() < deadline:
            stamp = warm_up()
            if (recorder.wait_for(stamp, WARM_UP_WAIT_S, (*PERIOD_TOPICS, interface.CLOCK_TOPIC))
                    and delivered(recorder)):
                recorder.start(stamp + 1)
                return recorder
    recorder.close()
    raise EvaluationError(f'the bag recorder could not connect to nav_sim in '
                          f'{namespace} within {timeout} s')


def _open_recorder(path: Path, env: NavigationEnv, timeout: float = 10.0) -> Any:
    """Return a bag recorder on the env's sim (:func:`open_recorder`)."""
    # cmd_vel is the env's own publisher: it delivers to the recorder once it has matched the
    # recorder's subscription (the sim's subscription is the other one)
    commands = env.client.pub_cmd
    return open_recorder(path, env.namespace, lambda: env.client.reset(0, TRAIN)[0].stamp_ns,
                         lambda _: commands.get_subscription_count() >= 2, timeout,
                         cmd_vel_stamped=env.config.cmd_vel_stamped)


def env_for_run(config: TrainConfig, record: bool, sim: str = 'embedded') -> NavigationEnv:
    """Return the training environment of a run (same sim, actions and reward weights)."""
    sim_params = dict(config.sim_params)
    if record:
        sim_params['publish_clock'] = True
    return NavigationEnv(config.env_config(sim=sim, namespace='',
                                           sim_timeout=max(config.sim_timeout, 5.0),
                                           sim_params=sim_params))


def output_dir(out: Path) -> Path:
    """Create an evaluation's output directory (``--out``); a one-line error if it cannot be."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EvaluationError(f'cannot create the output directory {out} ({exc.strerror}); '
                              'choose another --out') from None
    return out


def evaluate(run_dir: Path, sets: list[EvalSet], out: Path | None = None,
             record: bool = True, *, live_port: int = 0,
             sim_params: dict[str, Any] | None = None) -> dict[str, Any]:
    """Evaluate every set and write results.json / results.md / episodes.csv under ``out``.

    ``sim_params`` plays the run's policies in another world or look
    (``TrainConfig.in_world``); results.json's ``config`` says which.
    """
    config = run_config(run_dir)
    if sim_params:
        try:
            config = config.in_world(sim_params)
        except TrainConfigError as exc:
            raise EvaluationError(f'--sim-params: {exc}') from None
    out = output_dir(out or run_dir / EVAL)
    env = env_for_run(config, record)
    try:
        if live_port:  # --live: this process serves the Foxglove live view
            print(f'live view: open {env.start_live(live_port)} in Foxglove', flush=True)
        entries = [evaluate_set(env, run_dir, s, out, record) for s in sets]
    finally:
        env.close()
    return write_results(out, run_dir, config, entries)


def write_results(out: Path, run_dir: Path, config: TrainConfig, entries: list[dict[str, Any]],
                  **extra: Any) -> dict[str, Any]:
    """Write ``results.json``, ``results.md`` and ``episodes.csv`` under ``out``; return them."""
    results = {'run_dir': str(run_dir), 'arena': arena_description(config.sim_params),
               'config': eval_settings(config), **extra, 'sets': entries}
    (out / RESULTS).write_text(json.dumps(results, indent=1))
    (out / RESULTS_TABLE).write_text(results_markdown(entries))
    (out / EPISODES_CSV).write_text(metrics.episodes_csv(
        (e['name'], e['episodes']) for e in entries))
    return results


def results_markdown(entries: list[dict[str, Any]]) -> str:
    """Return the Markdown results table, one row per evaluated set with its seed range."""
    rows = [metrics.summary_row(f"{e['label']} ({seed_range(e['seeds'])})",
                                metrics.SetSummary(**e['summary'])) for e in entries]
    return metrics.markdown_table(metrics.TABLE_COLUMNS, rows) + '\n'


def rerun(run_dir: Path, trace: dict) -> list[int]:
    """Replay a traced episode's seed with the same policy; returns the actions it took."""
    config = run_config(run_dir)
    policy = make_policy(trace['policy'], run_dir, trace['checkpoint'])
    env = env_for_run(config, record=False)
    try:
        _, replay, _ = run_episode(env, policy, trace['seed'], trace['split'])
    finally:
        env.close()
    return [s['action'] for s in replay['steps']]
