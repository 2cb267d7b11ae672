"""Deterministic evaluation of a training run on fixed seeds (Part 4 of the workshop).

    ros2 run nav_eval evaluate RUN_DIR [--sets ...] [--train-seeds 101-110]
                                       [--heldout-seeds 201-210] [--no-record] [--video]

Default sets, all on the same scenarios per split: the random policy on the training seeds
(baseline), the final DQN on the training seeds and on the held-out seeds, and the early
checkpoint (the first one after step 0) on both, for the early-vs-final comparison.  The DQN acts
with ``predict(deterministic=True)``; the environment is built from the run's own
``config.yaml`` (sim settings, action speeds, episode limit), so preprocessing and action timing
are those of training.  Writes ``RUN_DIR/eval/``: ``results.json``, ``results.md``,
``episodes.csv``, per-episode traces (``traces/<set>/seed_<n>.json`` + ``_frames.npz``) and one
rosbag2/MCAP bag per set under ``bags/<set>/``; with ``--video``, MP4 videos of the report's
representative episodes under ``videos/`` (``nav_eval.video``).  The same evaluation twice gives
identical files (wall-clock time is only printed).

A diagnosis, on request only: ``explore_train`` / ``explore_heldout`` play the final model with
training's final epsilon (``policies.ExploringDQNPolicy``), into another ``--out`` than
``RUN_DIR/eval`` so that they never replace the evaluation.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval import metrics
from nav_eval.errors import EvaluationError
from nav_eval.policies import DQNPolicy, ExploringDQNPolicy, Policy, RandomPolicy
from nav_gym import run_dir as layout
from nav_gym.checkpoints import checkpoints
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.env import NavigationEnv
from nav_gym.errors import TrainConfigError
from nav_gym.live_hooks import add_live_argument
from nav_gym.timing import quiet_learner_threads
from nav_gym.train_config import TrainConfig
from nav_sim import interface
from nav_sim.config import SimConfig, normalise_split

TRAIN_SEEDS = tuple(range(101, 111))
HELDOUT_SEEDS = tuple(range(201, 211))
SET_LABELS = {
    'random_train': 'Random policy, training seeds', 'dqn_train': 'DQN final, training seeds',
    'dqn_heldout': 'DQN final, held-out seeds', 'early_train': 'DQN early, training seeds',
    'early_heldout': 'DQN early, held-out seeds',
    # a diagnosis, not in the defaults: the final model with training's final exploration
    'explore_train': 'DQN final with training ε, training seeds',
    'explore_heldout': 'DQN final with training ε, held-out seeds'}
#: the workshop's evaluation: deterministic policies only
DEFAULT_SETS = ('random_train', 'dqn_train', 'dqn_heldout', 'early_train', 'early_heldout')
#: evaluation set kind (its name's first word) -> the policy that plays it
SET_POLICIES = {'random': 'random', 'dqn': 'dqn', 'early': 'dqn', 'explore': 'explore'}
#: where the sim was when the episode started (not part of the scenario; the bag has them)
SIM_COUNTERS = ('episode', 'period', 'stamp_ns')
WARM_UP_WAIT_S = 0.5  # how long a warm-up period may take to reach the recorder


@dataclass(frozen=True)
class EvalSet:
    """A policy evaluated on one split's seeds."""

    name: str
    label: str
    policy: str
    checkpoint: str | None
    split: str
    seeds: tuple[int, ...]


def parse_seeds(text: str) -> tuple[int, ...]:
    """'101-110' or '101,105,107' (or a mix) -> a tuple of non-negative seeds."""
    seeds: list[int] = []
    try:
        for part in text.split(','):
            lo, _, hi = part.strip().partition('-')
            seeds += list(range(int(lo), int(hi) + 1)) if hi else [int(lo)]
            if hi and int(hi) < int(lo):
                raise EvaluationError(f'bad seed range {part.strip()!r} in {text!r}: the first '
                                      f"seed must not exceed the last, e.g. '{hi}-{lo}'")
    except ValueError:
        raise EvaluationError(f"bad seed list {text!r}: use e.g. '101-110' or '101,102'") from None
    if not seeds or min(seeds) < 0:
        raise EvaluationError(f'bad seed list {text!r}: need at least one seed, all >= 0')
    return tuple(seeds)


def run_config(run_dir: Path) -> TrainConfig:
    """Return the run's TrainConfig, or raise EvaluationError saying what is wrong."""
    try:
        return layout.load_config(run_dir)
    except TrainConfigError as exc:
        raise EvaluationError(str(exc)) from None


def early_checkpoint(run_dir: Path) -> str | None:
    """Return the first checkpoint after step 0 (relative to the run directory), if any."""
    found = [(s, p) for s, p in checkpoints(run_dir) if s > 0]
    return str(found[0][1].relative_to(run_dir)) if found else None


def plan_sets(run_dir: Path, names: list[str], train_seeds: tuple[int, ...],
              heldout_seeds: tuple[int, ...], final: str = 'final_model.zip',
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
        seeds = train_seeds if split == 'train' else heldout_seeds
        if kind == 'early' and early is None:
            print(f'skipping {name}: the run has no checkpoint after step 0')
            continue
        checkpoint = {'random': None, 'dqn': final, 'early': early, 'explore': final}[kind]
        if checkpoint is not None and not (run_dir / checkpoint).is_file():
            raise EvaluationError(f'{name}: checkpoint {run_dir / checkpoint} not found; '
                                  'finish (or --resume) the training run first')
        out.append(EvalSet(name, SET_LABELS[name], SET_POLICIES[kind], checkpoint, split, seeds))
    return out


def run_episode(env: NavigationEnv, policy: Policy, seed: int, split: str,
                recorder: Any = None) -> tuple[metrics.EpisodeResult, dict, np.ndarray]:
    """One episode: returns its result, its per-step trace and its observations."""
    obs, info = env.reset(seed=seed, options={'split': split})
    if recorder is not None:
        _recorded(recorder, env.last_stamp_ns)
    policy.begin_episode(seed)
    frames, steps = [obs], []
    total, truncated, event = 0.0, False, 'none'
    step_info: dict[str, Any] = {'distance': info['distance'], 'path_length': 0.0}
    while True:
        action, q_values = policy.act(obs)
        env.note_q_values(q_values)  # for the live view and the bag's /visnav/step
        obs, reward, terminated, truncated, step_info = env.step(action)
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
                      'q_values': q_values})
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
    from nav_eval.bags import PERIOD_TOPICS
    if not recorder.wait_for(stamp_ns, timeout, PERIOD_TOPICS):
        print(f'warning: the bag misses messages of the period stamped {stamp_ns} ns',
              flush=True)


def arena_description(sim_params: dict[str, Any]) -> dict[str, Any]:
    """Arena geometry for top-down plots (loads the MJCF; renders nothing)."""
    from nav_sim.world import World
    config = SimConfig.from_params(sim_params)
    world = World(config)
    g = world.geometry
    return {'half_size': g.half_size, 'robot_radius': g.robot_radius,
            'goal_radius': config.goal_radius, 'goal_marker_radius': config.goal_marker_radius,
            'shapes': [{'name': s.name, 'kind': s.kind, 'half_x': s.half_x, 'half_y': s.half_y}
                       for s in g.shapes]}


def make_policy(kind: str, run_dir: Path, checkpoint: str | None) -> Policy:
    """Return the policy of an evaluation set or trace (``SET_POLICIES``' values)."""
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
    layout.trace_path(out, eval_set.name, 0).parent.mkdir(parents=True, exist_ok=True)
    recorder = _open_recorder(out / 'bags' / eval_set.name, env) if record else None
    scene_writer = None
    if recorder is not None:  # the live view's scene topics go into the bag too
        from nav_eval.bag_scene import BagSceneWriter
        scene_writer = BagSceneWriter(recorder, env.config.sim_params)
        env.observers.append(scene_writer)
    results = []
    try:
        for seed in eval_set.seeds:
            result, trace, frames = run_episode(env, policy, seed, eval_set.split, recorder)
            results.append(result)
            meta = {'set': eval_set.name, 'policy': eval_set.policy,
                    'checkpoint': eval_set.checkpoint, **exploration}
            trace = {**meta, **trace}
            trace_file = layout.trace_path(out, eval_set.name, seed)
            trace_file.write_text(json.dumps(trace, indent=1))
            np.savez_compressed(layout.frames_path(trace_file), obs=frames)
            if recorder is not None:
                recorder.annotate({**meta, **result.to_dict()})
            print(f'  {eval_set.name:<14} seed {seed:>4}: {result.outcome:<9} '
                  f'{result.length:>4} steps  return {result.episode_return:+7.3f}  '
                  f'SPL {result.spl:.3f}', flush=True)
    finally:
        if scene_writer is not None:
            env.observers.remove(scene_writer)
        if recorder is not None:
            recorder.close()
    summary = metrics.summarize(results)
    return {'name': eval_set.name, 'label': eval_set.label, 'policy': eval_set.policy,
            'checkpoint': eval_set.checkpoint, **exploration, 'split': eval_set.split,
            'seeds': list(eval_set.seeds), 'summary': summary.to_dict(),
            'episodes': [r.to_dict() for r in results]}


def _open_recorder(path: Path, env: NavigationEnv, timeout: float = 10.0) -> Any:
    """Return a bag recorder on the env's sim that the sim is known to deliver to.

    The sim can match the recorder's subscriptions some time after the recorder has matched
    its publishers; what it publishes before then never reaches the bag.  So the recorder
    starts paused and the sim is reset (a warm-up period, not written) until one whole
    control period has reached the recorder; the bag starts after it.
    """
    from nav_eval.bag_recorder import BagRecorder
    from nav_eval.bags import PERIOD_TOPICS, SIM_TOPICS
    if path.exists():
        import shutil
        shutil.rmtree(path)  # a re-run replaces the bag of the same set
    path.parent.mkdir(parents=True, exist_ok=True)
    # root names: the bag's topics are those of the live view and the Foxglove layout
    recorder = BagRecorder(path, namespace=env.namespace, paused=True, root_names=True)
    deadline = time.monotonic() + timeout
    # cmd_vel is the env's own publisher: it delivers to the recorder once it has matched the
    # recorder's subscription (the sim's subscription is the other one)
    commands = env.client.pub_cmd
    if recorder.wait_for_publishers(timeout, (*SIM_TOPICS, interface.CMD_VEL_TOPIC)):
        while time.monotonic() < deadline:
            frame, _ = env.client.reset(0, 'train')
            if (recorder.wait_for(frame.stamp_ns, WARM_UP_WAIT_S,
                                  (*PERIOD_TOPICS, interface.CLOCK_TOPIC))
                    and commands.get_subscription_count() >= 2):
                recorder.start(frame.stamp_ns + 1)
                return recorder
    recorder.close()
    raise EvaluationError(f'the bag recorder could not connect to nav_sim in '
                          f'{env.namespace} within {timeout} s')


def env_for_run(config: TrainConfig, record: bool, sim: str = 'embedded') -> NavigationEnv:
    """Return the training environment of a run (same sim, actions and reward weights)."""
    sim_params = dict(config.sim_params)
    if record:
        sim_params['publish_clock'] = True
    return NavigationEnv(config.env_config(sim=sim, namespace='',
                                           sim_timeout=max(config.sim_timeout, 5.0),
                                           sim_params=sim_params))


def evaluate(run_dir: Path, sets: list[EvalSet], out: Path | None = None,
             record: bool = True, *, live_port: int = 0) -> dict[str, Any]:
    """Evaluate every set and write results.json / results.md / episodes.csv under ``out``."""
    config = run_config(run_dir)
    out = out or run_dir / layout.EVAL
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EvaluationError(f'cannot create the output directory {out} ({exc.strerror}); '
                              'choose another --out') from None
    env = env_for_run(config, record)
    try:
        if live_port:  # --live: this process serves the Foxglove live view
            print(f'live view: open {env.start_live(live_port)} in Foxglove', flush=True)
        entries = [evaluate_set(env, run_dir, s, out, record) for s in sets]
    finally:
        env.close()
    results = {'run_dir': str(run_dir), 'arena': arena_description(config.sim_params),
               'config': layout.eval_settings(config),
               'sets': entries}
    (out / layout.RESULTS).write_text(json.dumps(results, indent=1))
    (out / 'results.md').write_text(results_markdown(entries))
    (out / 'episodes.csv').write_text(metrics.episodes_csv(
        (e['name'], e['episodes']) for e in entries))
    return results


def results_markdown(entries: list[dict[str, Any]]) -> str:
    """Return the Markdown results table, one row per evaluated set with its seed range."""
    rows = [metrics.summary_row(f"{e['label']} ({_seed_range(e['seeds'])})",
                                metrics.SetSummary(**e['summary'])) for e in entries]
    return metrics.markdown_table(metrics.TABLE_COLUMNS, rows) + '\n'


def _seed_range(seeds: list[int]) -> str:
    contiguous = seeds == list(range(seeds[0], seeds[0] + len(seeds)))
    return f'{seeds[0]}–{seeds[-1]}' if contiguous and len(seeds) > 1 else ','.join(
        map(str, seeds))


def write_videos(run_dir: Path) -> None:
    """Write the videos of the report's representative episodes to RUN_DIR/eval/videos/."""
    from nav_eval import report  # matplotlib and ffmpeg only when asked for
    start = time.perf_counter()
    written = report.write_videos(report.load_run(run_dir), run_dir / layout.EVAL / 'videos')
    for caption, path, problem in written:
        print(f'video {path}: {caption}' if path else f'no video of {caption}: {problem}')
    if not written:
        print('no videos: no DQN episode to show (evaluate a dqn_* or early_* set)')
    print(f'wrote {sum(bool(p) for _, p, _ in written)} videos in '
          f'{time.perf_counter() - start:.1f} s')


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-eval-evaluate`` command: evaluate the sets and print the results table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('run_dir', type=Path, help='training run directory')
    parser.add_argument('--sets', default=','.join(DEFAULT_SETS),
                        help=f'comma-separated evaluation sets (default: all of {DEFAULT_SETS}; '
                        'a diagnosis, with --out elsewhere: explore_train, explore_heldout)')
    parser.add_argument('--train-seeds', default='101-110')
    parser.add_argument('--heldout-seeds', default='201-210')
    parser.add_argument('--checkpoint', default='final_model.zip',
                        help='final model, relative to the run directory')
    parser.add_argument('--early-checkpoint', help='early checkpoint (default: the first '
                        'after step 0)')
    parser.add_argument('--out', type=Path, help='output directory (default RUN_DIR/eval)')
    parser.add_argument('--no-record', action='store_true', help='do not write MCAP bags')
    parser.add_argument('--video', action='store_true', help='also write MP4 videos of the '
                        "report's representative episodes to RUN_DIR/eval/videos/")
    add_live_argument(parser)
    args = parser.parse_args(strip_ros_args(argv))
    quiet_learner_threads()  # the policy's forward passes must not spin against the sim

    def body() -> int:
        eval_dir = (args.run_dir / layout.EVAL).resolve()
        writes_eval = args.out is None or args.out.resolve() == eval_dir
        if args.video and not writes_eval:
            raise EvaluationError('--video reads the evaluation where the report does, in '
                                  'RUN_DIR/eval: leave out --out')
        sets = plan_sets(args.run_dir, [s for s in args.sets.split(',') if s],
                         parse_seeds(args.train_seeds), parse_seeds(args.heldout_seeds),
                         args.checkpoint, args.early_checkpoint)
        if writes_eval and any(s.policy == 'explore' for s in sets):
            raise EvaluationError('the explore sets are a diagnosis, not the evaluation: write '
                                  'them elsewhere with --out (e.g. --out RUN_DIR/eval_explore)')
        start = time.perf_counter()
        results = evaluate(args.run_dir, sets, args.out, record=not args.no_record,
                           live_port=args.live)
        print(results_markdown(results['sets']))
        print(f'evaluated {sum(len(s.seeds) for s in sets)} episodes in '
              f'{time.perf_counter() - start:.1f} s; results in '
              f"{args.out or args.run_dir / 'eval'}")
        if args.video:
            write_videos(args.run_dir)
        return 0

    run_command('nav-eval-evaluate', body)


if __name__ == '__main__':
    main()
