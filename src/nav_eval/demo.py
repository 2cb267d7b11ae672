"""``make demo``: the policy node drives a realtime sim through one episode, at wall-clock pace.

    visnav-demo [--model RUN] [--seed 101] [--split train] [--rate 1] [--live [PORT]]

Starts the sim node in ``realtime`` mode and the policy node (``ros2 run nav_gym policy``), each in
its own process, as a robot would run them: nobody waits for the policy.  With ``--model RUN`` (a
run directory, a checkpoint ``.zip`` or an export, ``RUN/export``, which runs on ONNX Runtime) the
trained policy drives; without one, the image-only
servo baseline (``policy:=servo``, :mod:`nav_gym.policy.servo`) drives the robot to the
goal.  Prints the scenario, then each control period: the action the sim applied, the wheel speeds,
pose, distance and event, and how late the command was.  With ``--live`` this process serves the
Foxglove live view (camera, observation, 3D scene, the episode's numbers and the policy's decisions
on the Policy node tab).  The sim alone, driven by a script in lockstep, is ``nav-sim-demo``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.evaluation.closed_loop import ClosedLoop, LoopSettings, run_episode
from nav_gym.cli import run_command, strip_ros_args
from nav_gym.policy.actors import model_file, run_of
from nav_gym.policy.exported import is_export, read_export
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import load_config, run_settings
from nav_gym.training.timing import quiet_learner_threads
from nav_sim.core.config import HELDOUT, TRAIN
from nav_sim.core.scenarios import DEMO_SEED
from nav_sim.viz.options import add_live_argument

PROG = 'visnav-demo'


class PrintSteps:
    """An episode observer that prints the scenario and one line per control period."""

    def __init__(self, ctrl_dt: float) -> None:
        """Print periods of ``ctrl_dt`` seconds of sim time."""
        self.period_ns = round(ctrl_dt * 1e9)
        self.q_values: Any = None

    def note_q_values(self, q_values: Any) -> None:
        """Keep the Q-values of the next period's command."""
        self.q_values = q_values

    def on_reset(self, stamp_ns: int, rgb: np.ndarray, obs: np.ndarray,
                 info: dict[str, Any]) -> None:
        """Print the scenario and the table's header."""
        sc = info['scenario']
        print(f"scenario: seed={sc['seed']} split={sc['split']} layout={sc['layout']} "
              f"start={sc['start']} goal={sc['goal']} initial_distance="
              f"{sc['initial_distance']:.3f} m", flush=True)
        print(f"{'step':>4} {'action':>8} {'x':>7} {'y':>7} {'yaw':>7} {'dist':>6} "
              f"{'late':>5} event", flush=True)

    def on_step(self, stamp_ns: int, rgb: np.ndarray, obs: np.ndarray, action: int,
                reward: float, info: dict[str, Any], done: bool) -> None:
        """Print one period: the action applied, the pose, the distance and the event."""
        image = info.get('decision_image_stamp_ns')  # periods from the image to the command
        late = '–' if image is None else str(max(0, round((stamp_ns - image) / self.period_ns
                                                          ) - 1))
        x, y, yaw = info['pose']
        print(f"{info['step']:>4} {info['action_name']:>8} {x:>7.3f} {y:>7.3f} {yaw:>7.3f} "
              f"{info['distance']:>6.3f} {late:>5} {info['event']}", flush=True)


def demo_config(model: str | None) -> TrainConfig:
    """Return the settings the demo's sim runs with: the model's run's, or the defaults."""
    if model is None:
        return TrainConfig()
    if is_export(model):  # an export carries its run's settings
        return TrainConfig(**run_settings(read_export(model).config))
    run = run_of(model_file(model))
    return load_config(run) if run is not None else TrainConfig()


def run(model: str | None, seed: int, split: str, rate: float, live_port: int) -> int:
    """Drive one episode with the policy node; returns a process exit code."""
    config = demo_config(model)
    loop = LoopSettings.of(config, rate)
    policy = {'model': str(Path(model).expanduser()), 'policy': 'dqn'} if model else \
        {'policy': 'servo'}
    who = f'the model {model}' if model else 'the image-only servo (no --model given)'
    print(f'starting the sim (realtime at {rate:g}x) and the policy node with {who} ...',
          flush=True)
    live = None
    if live_port:
        from nav_gym.env.live_view import EnvLive
        from nav_sim.viz.topics import CLOSED_LOOP_TOPICS
        live = EnvLive(live_port, config.sim_params, topics=CLOSED_LOOP_TOPICS)
        print(f'live view: open {live.url} in Foxglove (layout: config/foxglove/visnav.json)',
              flush=True)
    printer = PrintSteps(loop.ctrl_dt)
    start = time.monotonic()
    try:
        with ClosedLoop(config, policy, loop) as closed:
            assert closed.graph is not None
            if live is not None:
                closed.graph.forward = live.forward
            observers = [printer] + ([live] if live is not None else [])
            with closed.dead_named():
                result, trace, _, latency = run_episode(closed.graph, seed, split,
                                                        config.env_config(), loop, observers)
    finally:
        if live is not None:
            live.close()
    late = sum(1 for s in latency.sim if s > 0.0)
    print(f'episode over: {result.outcome} after {result.length} periods '
          f'({time.monotonic() - start:.1f} s wall clock), return {result.episode_return:+.3f}; '
          f'{late} of {len(latency.sim)} answers acted a period late or more; the policy node '
          'sent a zero Twist on exit', flush=True)
    return 0


def main(argv: list[str] | None = None) -> None:
    """Run the ``visnav-demo`` command (``make demo``)."""
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument('--model', help='a run directory, a checkpoint .zip or an export '
                        '(RUN/export, on ONNX Runtime) (default: the image-only servo baseline)')
    parser.add_argument('--seed', type=int, default=DEMO_SEED)
    parser.add_argument('--split', default=TRAIN, choices=(TRAIN, HELDOUT))
    parser.add_argument('--rate', type=float, default=1.0,
                        help='sim seconds per wall-clock second (default 1: wall-clock pace)')
    add_live_argument(parser, 'the Foxglove live view')
    args = parser.parse_args(strip_ros_args(argv))
    if not 0.0 < args.rate < float('inf'):
        parser.error(f'--rate must be a number above zero, got {args.rate}')
    quiet_learner_threads()

    def body() -> int:
        if args.model:  # a clear error before anything starts
            read_export(args.model) if is_export(args.model) else model_file(args.model)
        return run(args.model, args.seed, args.split, args.rate, args.live)

    run_command(PROG, body)
