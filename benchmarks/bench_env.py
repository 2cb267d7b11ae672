"""Env steps/s through ROS vs. in process, and DQN wall-clock by OpenMP wait policy.

Measured side by side in one run.

    .venv/bin/python benchmarks/bench_env.py [--steps 2000] [--dqn-steps 4000]

1. The same random action sequence (seeded) drives both loops, with the same work per step:
   one control period (action repeat with goal/collision checks), one camera render, the
   conversion to a (3, 84, 84) observation and the reward; an episode end triggers a reset.
   The ROS loop adds the env's lockstep round trip through the nav_sim node.
2. A short DQN('CnnPolicy') run with the workshop settings (learning starts after
   ``--learning-starts`` steps) through the ROS env: the share of wall-clock time spent inside
   ``env.step``/``env.reset`` against the learner.  Target: under 20% on a 2-core machine.
   It runs ``--dqn-repeats`` times alternating, each in a child process because OpenMP reads
   its settings once: with passive OpenMP waits (``OMP_WAIT_POLICY=PASSIVE``) and with
   libgomp's default waits.  Wall-clock time decides which is faster (training's default,
   see ``nav_gym.training.timing.quiet_learner_threads``); the env share is a diagnostic.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from typing import Any

os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

from nav_gym.env.actions import action_twists  # noqa: E402
from nav_gym.env.config import EnvConfig  # noqa: E402
from nav_gym.env.navigation import NavigationEnv  # noqa: E402
from nav_gym.env.observation import rgb_to_observation  # noqa: E402
from nav_gym.env.reward import reward_terms
from nav_sim.core.kinematics import twist_to_wheels
from nav_sim.core.sim import NavSim  # noqa: E402


class EnvTimer(gym.Wrapper):
    """Accumulates the seconds spent inside ``reset()`` and ``step()``."""

    def __init__(self, env: gym.Env) -> None:
        """Wrap ``env`` with zeroed counters."""
        super().__init__(env)
        self.env_seconds = 0.0
        self.env_steps = 0

    def reset(self, **kwargs: Any) -> Any:
        """Reset the env, timed."""
        start = time.perf_counter()
        try:
            return self.env.reset(**kwargs)
        finally:
            self.env_seconds += time.perf_counter() - start

    def step(self, action: Any) -> Any:
        """Step the env, timed."""
        start = time.perf_counter()
        try:
            return self.env.step(action)
        finally:
            self.env_seconds += time.perf_counter() - start
            self.env_steps += 1


def actions(n: int) -> np.ndarray:
    """Return the seeded random action sequence both loops use."""
    return np.random.default_rng(0).integers(0, 3, size=n)


def in_process(steps: int, config: EnvConfig) -> float:
    """Return steps/s of the env's work without ROS (NavSim, observation, reward, resets)."""
    sim = NavSim()
    commands = {a: twist_to_wheels(*v, sim.config)
                for a, v in enumerate(action_twists(config))}  # NavigationEnv's actions
    seed = 0
    try:
        start = time.perf_counter()
        sim.reset(seed, 'train')
        rgb_to_observation(sim.render())
        distance, count = sim.distance, 0
        for action in actions(steps):
            result = sim.step(commands[int(action)])
            rgb_to_observation(sim.render())
            reward_terms(distance, result.distance, result.event, config)
            distance, count = result.distance, count + 1
            if result.done or count >= config.max_episode_steps:
                seed, count = seed + 1, 0
                sim.reset(seed, 'train')
                rgb_to_observation(sim.render())
                distance = sim.distance
        return steps / (time.perf_counter() - start)
    finally:
        sim.close()


def through_ros(steps: int, config: EnvConfig) -> float:
    """Return steps/s of NavigationEnv through the nav_sim node."""
    env = NavigationEnv(config)
    try:
        env.reset(seed=0)
        for action in actions(50):  # warm-up
            if any(env.step(int(action))[2:4]):
                env.reset()
        start = time.perf_counter()
        env.reset(seed=0)
        for action in actions(steps):
            if any(env.step(int(action))[2:4]):
                env.reset()
        return steps / (time.perf_counter() - start)
    finally:
        env.close()


def dqn_share(steps: int, learning_starts: int, config: EnvConfig
              ) -> tuple[float, float, float, float]:
    """(env seconds, wall seconds, steps/s, env share) of a short DQN run through ROS."""
    from stable_baselines3 import DQN

    from bench_learner import WORKSHOP
    from nav_gym.training.config import build
    timer = EnvTimer(NavigationEnv(config))
    try:  # SB3's DQN at the workshop's settings (config/workshop.yaml: gradient_steps 1 too)
        kwargs = {**build(str(WORKSHOP), {}).dqn_kwargs(), 'learning_starts': learning_starts,
                  'buffer_size': max(steps, 1000), 'device': 'cpu'}
        model = DQN('CnnPolicy', timer, verbose=0, **kwargs)
        start = time.perf_counter()
        model.learn(steps)
        wall = time.perf_counter() - start
    finally:
        timer.close()
    return timer.env_seconds, wall, steps / wall, timer.env_seconds / wall


def dqn_share_child(args: argparse.Namespace, passive: bool) -> dict[str, float]:
    """Run ``dqn_share`` in a fresh interpreter (OpenMP reads OMP_WAIT_POLICY once)."""
    env = {k: v for k, v in os.environ.items() if k != 'OMP_WAIT_POLICY'}
    if passive:
        env['OMP_WAIT_POLICY'] = 'PASSIVE'
    command = [sys.executable, __file__, '--dqn-only', '--dqn-steps', str(args.dqn_steps),
               '--learning-starts', str(args.learning_starts)]
    out = subprocess.run(command, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def report_dqn(label: str, r: dict[str, float], steps: int, learning_starts: int) -> None:
    """Print one DQN run's wall-clock time, steps/s and env share."""
    env_per_step = r['env_s'] / steps
    # the rest of the wall time is the learner and SB3's bookkeeping (charged here to the
    # learning steps, which favours the env a little): extrapolate to 50k steps / 2k starts
    learner_per_step = (r['wall'] - r['env_s']) / max(steps - learning_starts, 1)
    full = env_per_step * 50_000 / (env_per_step * 50_000 + learner_per_step * 48_000)
    print(f'  {label}: {r["wall"]:.1f} s, {steps / r["wall"]:.0f} steps/s; env '
          f'{env_per_step * 1e3:.2f} ms/step, learner {learner_per_step * 1e3:.2f} ms per '
          f'learning step')
    print(f'    env share of this run\'s wall-clock: {r["share"]:6.1%}; extrapolated to 50k '
          f'steps (2k before learning): {full:6.1%}  (target < 20%: '
          f"{'met' if full < 0.2 else 'NOT met'})")


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--steps', type=int, default=2000)
    parser.add_argument('--repeats', type=int, default=2, help='alternating runs; best kept')
    parser.add_argument('--dqn-steps', type=int, default=4000)
    parser.add_argument('--learning-starts', type=int, default=160,
                        help="4%% of the steps, as 2,000 of the workshop's 50,000")
    parser.add_argument('--dqn-repeats', type=int, default=3,
                        help='alternating DQN runs per OpenMP wait policy')
    parser.add_argument('--dqn-comparison-only', action='store_true',
                        help='skip the env steps/s measurement')
    parser.add_argument('--dqn-only', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args()
    config = EnvConfig(sim='embedded')
    if args.dqn_only:  # child process: one DQN measurement as JSON (policy from the parent)
        env_s, wall, _, share = dqn_share(args.dqn_steps, args.learning_starts, config)
        print(json.dumps({'env_s': env_s, 'wall': wall, 'share': share}))
        return
    if not args.dqn_comparison_only:
        report_env(args, config)
    print(f'DQN CnnPolicy, {args.dqn_steps} steps ({args.learning_starts} before learning '
          f'starts), through the ROS env, {args.dqn_repeats} alternating runs per policy:')
    runs: dict[str, list[dict[str, float]]] = {'passive': [], 'default': []}
    for _ in range(args.dqn_repeats):
        runs['passive'].append(dqn_share_child(args, passive=True))
        runs['default'].append(dqn_share_child(args, passive=False))
    for label, results in runs.items():
        walls = [r['wall'] for r in results]
        for r in results:
            report_dqn(f'OpenMP {label} waits', r, args.dqn_steps, args.learning_starts)
        print(f'  {label}: wall-clock mean {np.mean(walls):.1f} s, range {min(walls):.1f}-'
              f'{max(walls):.1f} s, env share mean '
              f"{np.mean([r['share'] for r in results]):.1%}")
    passive = [r['wall'] for r in runs['passive']]
    default = [r['wall'] for r in runs['default']]
    overlap = max(min(passive), min(default)) <= min(max(passive), max(default))
    print(f'  wall-clock passive / default (means): {np.mean(passive) / np.mean(default):6.1%}'
          f"; ranges {'overlap: within the noise' if overlap else 'do not overlap'}")


def report_env(args: argparse.Namespace, config: EnvConfig) -> None:
    """Print env steps/s through ROS against the same work in process."""
    core, ros = [], []
    for _ in range(args.repeats):
        core.append(in_process(args.steps, config))
        ros.append(through_ros(args.steps, config))
    best_core, best_ros = max(core), max(ros)
    print(f'env steps/s, {args.steps} random-action steps, best of {args.repeats} '
          'alternating runs')
    print(f'  sim core in process (step+render+obs+reward): {best_core:7.0f} /s  '
          f'runs: {[round(v) for v in core]}')
    print(f'  NavigationEnv through the nav_sim node:       {best_ros:7.0f} /s  '
          f'runs: {[round(v) for v in ros]}')
    print(f'  ratio ROS env / in process:                   {best_ros / best_core:7.1%}')

if __name__ == '__main__':
    main()
