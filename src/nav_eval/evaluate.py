"""Deterministic evaluation of a training run on fixed seeds (Part 4 of the workshop).

    ros2 run nav_eval evaluate RUN_DIR [--sets ...] [--train-seeds 101-110]
                                       [--heldout-seeds 201-210] [--no-record] [--video]
                                       [--sim-params '{world: rooms.xml}' --out DIR]

Default sets, all on the same scenarios per split: the random policy on the training seeds
(baseline), the final DQN on the training seeds and on the held-out seeds, and the early
checkpoint (the first one after step 0) on both, for the early-vs-final comparison
(:mod:`nav_eval.evaluation.sets`).  Writes ``RUN_DIR/eval/`` (:mod:`nav_eval.evaluation.runner`):
``results.json``, ``results.md``, ``episodes.csv``, per-episode traces and one rosbag2/MCAP bag
per set; with ``--video``, MP4 videos of the report's representative episodes under ``videos/``
(:mod:`nav_eval.reporting.videos`).  The same evaluation twice gives identical files
(wall-clock time is only printed).

A diagnosis, on request only: ``explore_train`` / ``explore_heldout`` play the final model with
training's final epsilon (``ExploringDQNPolicy``), into another ``--out`` than ``RUN_DIR/eval``
so that they never replace the evaluation.  So does ``--sim-params``: the run's policies in
another world or look (transfer, unseen looks), written to another ``--out``.

``--closed-loop [--realtime-rate 1,4]``: the final model in lockstep and driving a realtime sim
through the policy node at each rate, on the same seeds (default held-out 201-250; training
seeds only if ``--train-seeds`` is given), into ``RUN_DIR/eval_closed_loop``
(:mod:`nav_eval.evaluation.closed_loop`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from nav_eval.errors import EvaluationError
from nav_eval.evaluation.closed_loop import DEFAULT_RATES, evaluate_closed_loop
from nav_eval.evaluation.runner import evaluate, results_markdown
from nav_eval.evaluation.sets import DEFAULT_SETS, plan_sets
from nav_eval.reporting.closed_loop import closed_loop_latency_table
from nav_eval.seeds import (
    CLOSED_LOOP_HELDOUT,
    WORKSHOP_HELDOUT,
    WORKSHOP_TRAIN,
    add_many_episodes_argument,
    check_episodes,
    parse_seeds,
    seed_text,
)
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.training.config import coerce
from nav_gym.training.run_dir import CLOSED_LOOP, EVAL, FINAL_MODEL, VIDEOS
from nav_gym.training.timing import quiet_learner_threads
from nav_sim.core.config import HELDOUT, TRAIN
from nav_sim.viz.options import add_live_argument


def print_videos(run_dir: Path) -> None:
    """Write the report's representative episodes as videos to RUN_DIR/eval/videos/; say so."""
    from nav_eval.reporting.run_inputs import load_run
    from nav_eval.reporting.videos import write_run_videos  # matplotlib, ffmpeg
    start = time.perf_counter()
    written = write_run_videos(load_run(run_dir), run_dir / EVAL / VIDEOS)
    for caption, path, problem in written:
        print(f'video {path}: {caption}' if path else f'no video of {caption}: {problem}')
    if not written:
        print('no videos: no DQN episode to show (evaluate a dqn_* or early_* set)')
    print(f'wrote {sum(bool(p) for _, p, _ in written)} videos in '
          f'{time.perf_counter() - start:.1f} s')


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-eval-evaluate`` command: evaluate the sets and print the results table."""
    args = command_parser().parse_args(strip_ros_args(argv))
    quiet_learner_threads()  # the policy's forward passes must not spin against the sim
    if args.closed_loop:
        run_command('nav-eval-evaluate', lambda: closed_loop(args))
    run_command('nav-eval-evaluate', lambda: lockstep(args))


def command_parser() -> argparse.ArgumentParser:
    """Return the command's argument parser."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('run_dir', type=Path, help='training run directory')
    parser.add_argument('--sets', default=','.join(DEFAULT_SETS),
                        help=f'comma-separated evaluation sets (default: all of {DEFAULT_SETS}; '
                        'a diagnosis, with --out elsewhere: explore_train, explore_heldout)')
    parser.add_argument('--train-seeds', help=f'default {seed_text(WORKSHOP_TRAIN)} (with '
                        '--closed-loop: none)')
    parser.add_argument('--heldout-seeds', help=f'default {seed_text(WORKSHOP_HELDOUT)} (with '
                        f'--closed-loop: {seed_text(CLOSED_LOOP_HELDOUT)})')
    parser.add_argument('--checkpoint', default=FINAL_MODEL,
                        help='final model, relative to the run directory')
    parser.add_argument('--early-checkpoint', help='early checkpoint (default: the first '
                        'after step 0)')
    parser.add_argument('--out', type=Path, help='output directory (default RUN_DIR/eval)')
    parser.add_argument('--no-record', action='store_true', help='do not write MCAP bags')
    parser.add_argument('--sim-params', help="play the run's policies in another world or "
                        "look, into another --out: sim parameters over the run's, e.g. "
                        "'{world: rooms.xml}' (the world brings its own settings and episode "
                        "limit) or '{randomize_look: true}' (docs/worlds.md)")
    parser.add_argument('--video', action='store_true', help='also write MP4 videos of the '
                        "report's representative episodes to RUN_DIR/eval/videos/")
    parser.add_argument('--closed-loop', action='store_true', help='evaluate the final model '
                        'in lockstep and in real time (the policy node driving a realtime sim) '
                        f'on the same seeds, into RUN_DIR/{CLOSED_LOOP}')
    parser.add_argument('--realtime-rate', type=parse_rates, default=DEFAULT_RATES,
                        metavar='R[,R...]', help='with --closed-loop: sim seconds per wall-clock '
                        'second, one closed-loop set per rate (default 1,4)')
    add_many_episodes_argument(parser)
    add_live_argument(parser)
    return parser


def lockstep(args: argparse.Namespace) -> int:
    """Evaluate the sets in lockstep (the default); print the table; return the exit code."""
    eval_dir = (args.run_dir / EVAL).resolve()
    writes_eval = args.out is None or args.out.resolve() == eval_dir
    if args.video and not writes_eval:
        raise EvaluationError('--video reads the evaluation where the report does, in '
                              'RUN_DIR/eval: leave out --out')
    sets = plan_sets(args.run_dir, [s for s in args.sets.split(',') if s],
                     parse_seeds(args.train_seeds or seed_text(WORKSHOP_TRAIN)),
                     parse_seeds(args.heldout_seeds or seed_text(WORKSHOP_HELDOUT)),
                     args.checkpoint, args.early_checkpoint)
    check_episodes(sum(len(s.seeds) for s in sets), args.many_episodes)
    if writes_eval and any(s.policy == 'explore' for s in sets):
        raise EvaluationError('the explore sets are a diagnosis, not the evaluation: write '
                              'them elsewhere with --out (e.g. --out RUN_DIR/eval_explore)')
    sim_params = (coerce({'sim_params': args.sim_params}, '--sim-params')['sim_params']
                  if args.sim_params else None)
    if sim_params and writes_eval:
        raise EvaluationError("--sim-params plays the policy elsewhere, not the run's own "
                              'evaluation: write it with --out (e.g. --out '
                              'RUN_DIR/eval_rooms)')
    start = time.perf_counter()
    results = evaluate(args.run_dir, sets, args.out, record=not args.no_record,
                       live_port=args.live, sim_params=sim_params)
    print(results_markdown(results['sets']))
    print(f'evaluated {sum(len(s.seeds) for s in sets)} episodes in '
          f'{time.perf_counter() - start:.1f} s; results in '
          f'{args.out or args.run_dir / EVAL}')
    if args.video:
        print_videos(args.run_dir)
    return 0


def parse_rates(text: str) -> tuple[float, ...]:
    """Parse realtime rates ``1,4`` (an argparse type): finite numbers above zero."""
    try:
        rates = tuple(float(part) for part in text.split(',') if part.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a list of numbers: {text!r}') from None
    if not rates or not all(0.0 < r < float('inf') for r in rates):
        raise argparse.ArgumentTypeError(f'rates must be numbers above zero, got {text!r}')
    return rates


def closed_loop(args: argparse.Namespace) -> int:
    """Run ``--closed-loop``: lockstep and real time on the same seeds; print the table."""
    if args.video:
        raise EvaluationError('--video shows the lockstep evaluation: leave it out with '
                              '--closed-loop')
    seeds = {HELDOUT: parse_seeds(args.heldout_seeds or seed_text(CLOSED_LOOP_HELDOUT))}
    if args.train_seeds:
        seeds = {TRAIN: parse_seeds(args.train_seeds), **seeds}
    # each seed: once in lockstep, once per rate
    check_episodes(sum(map(len, seeds.values())) * (1 + len(args.realtime_rate)),
                   args.many_episodes)
    start = time.perf_counter()
    out = args.out or args.run_dir / CLOSED_LOOP
    results = evaluate_closed_loop(args.run_dir, seeds, args.realtime_rate, out,
                                   record=not args.no_record, checkpoint=args.checkpoint,
                                   live_port=args.live)
    print(results_markdown(results['sets']))
    print(closed_loop_latency_table(results['sets']))
    print(f"evaluated {sum(len(s['seeds']) for s in results['sets'])} episodes in "
          f'{time.perf_counter() - start:.1f} s; results in {out}')
    return 0


if __name__ == '__main__':
    main()
