"""Drive one scripted episode through the env and print every transition.

    nav-gym-episode [--seed 101] [--split train] [--namespace NS] [--sim auto]

Resets with a fixed seed, prints the scenario and initial distance, applies forward and turning
actions, prints action, reward (with its terms), distance, terminated and truncated after each
step, and confirms the robot stopped when the episode ended.
"""

from __future__ import annotations

import argparse

from nav_gym.cli import add_env_arguments, env_config, run_command, strip_ros_args
from nav_gym.env.navigation import ACTION_NAMES, NavigationEnv
from nav_sim.core.scenarios import DEMO_SEED

SCRIPT = [0] * 3 + [1] * 2 + [2] * 4 + [1] * 2 + [0] * 3 + [1] * 4


def scripted_episode(args: argparse.Namespace) -> int:
    """Drive one scripted episode, printing every transition; return the exit code."""
    env = NavigationEnv(env_config(args, max_episode_steps=len(SCRIPT)))
    try:
        _, info = env.reset(seed=args.seed, options={'split': args.split})
        s = info['scenario']
        print(f"scenario: seed {s['seed']}, split {s['split']}, layout {s['layout']}, start "
              f"{s['start']}, goal {s['goal']}")
        print(f"initial distance: {info['distance']:.3f} m")
        print(f"{'step':>4} {'action':>9} {'reward':>8} {'progress':>9} {'step':>6} "
              f"{'goal':>5} {'coll':>5} {'distance':>8} {'terminated':>10} {'truncated':>9}")
        for action in SCRIPT:
            _, reward, terminated, truncated, info = env.step(action)
            t = info['reward_terms']
            print(f"{info['step']:>4} {f'{action} {ACTION_NAMES[action]}':>9} {reward:>8.4f} "
                  f"{t['progress']:>9.4f} {t['step']:>6.2f} {t['goal']:>5.1f} "
                  f"{t['collision']:>5.1f} {info['distance']:>8.3f} {terminated!s:>10} "
                  f"{truncated!s:>9}")
            if terminated or truncated:
                wheels = info['wheels_after_stop']
                print(f"episode ended ({info['event'] if terminated else 'time limit'}); wheel "
                      f"speeds after stop: {wheels} -> robot "
                      f"{'stopped' if wheels == [0.0, 0.0] else 'STILL MOVING'}")
                return 0 if wheels == [0.0, 0.0] else 1
    finally:
        env.close()
    return 0


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-gym-episode`` command."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_env_arguments(parser)
    parser.add_argument('--seed', type=int, default=DEMO_SEED)
    parser.add_argument('--split', default='train')
    args = parser.parse_args(strip_ros_args(argv))
    run_command('nav-gym-episode', lambda: scripted_episode(args))


if __name__ == '__main__':
    main()
