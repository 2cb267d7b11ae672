"""Environment validation (Part 2 of the workshop) as reusable checks, no printing.

Each check returns a :class:`Check` with a measured value, so the command line, the report and the
tests all show the same evidence.  The scripted drivers use privileged state (pose, goal) to
*validate* the environment; the policy never sees it.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nav_gym.env.navigation import NavigationEnv
from nav_sim.core.events import EVENT_COLLISION, EVENT_GOAL

LEFT, FORWARD, RIGHT = 0, 1, 2


@dataclass(frozen=True)
class Check:
    """One line of the validation checklist."""

    name: str
    expected: str
    measured: str
    passed: bool


def heading_error(pose: tuple[float, float, float], goal: tuple[float, float]) -> float:
    """Return the signed angle (radians, in [-pi, pi]) from the robot's heading to the goal."""
    bearing = math.atan2(goal[1] - pose[1], goal[0] - pose[0])
    return math.remainder(bearing - pose[2], 2 * math.pi)


def drive_to_goal(env: NavigationEnv, seeds: range, max_steps: int = 400
                  ) -> tuple[int | None, list[dict[str, Any]]]:
    """Turn toward the goal and drive, using privileged state; returns a seed that succeeded."""
    for seed in seeds:
        _, info = env.reset(seed=seed)
        goal, pose, trace = info['goal'], info['pose'], []
        for _ in range(max_steps):
            error = heading_error(pose, goal)
            action = FORWARD if abs(error) < 0.2 else (LEFT if error > 0 else RIGHT)
            _, reward, terminated, truncated, step_info = env.step(action)
            trace.append({'reward': reward, 'terminated': terminated, 'truncated': truncated,
                          **step_info})
            pose = step_info['pose']
            if terminated or truncated:
                break
        if trace and trace[-1]['event'] == EVENT_GOAL:
            return seed, trace
    return None, []


def drive_forward(env: NavigationEnv, seed: int, max_steps: int = 400) -> list[dict[str, Any]]:
    """Drive straight ahead until something ends the episode."""
    env.reset(seed=seed)
    trace = []
    for _ in range(max_steps):
        _, reward, terminated, truncated, info = env.step(FORWARD)
        trace.append({'reward': reward, 'terminated': terminated, 'truncated': truncated, **info})
        if terminated or truncated:
            break
    return trace


def check_observation(env: NavigationEnv) -> list[Check]:
    """Check the observation's shape, dtype and range and that the action space is Discrete(3)."""
    obs, _ = env.reset(seed=101)
    after, *_ = env.step(FORWARD)
    ok_space = env.observation_space.contains(obs) and env.observation_space.contains(after)
    return [
        Check('Observation shape', '(3, 84, 84)', str(tuple(obs.shape)),
              obs.shape == (3, 84, 84) and after.shape == (3, 84, 84)),
        Check('Observation dtype', 'uint8', str(obs.dtype), obs.dtype == np.uint8),
        Check('Observation range', '0-255, not constant',
              f'min {int(obs.min())}, max {int(obs.max())}',
              ok_space and int(obs.max()) > int(obs.min())),
        Check('Action space', 'Discrete(3)', str(env.action_space),
              str(env.action_space) == 'Discrete(3)'),
    ]


def check_actions(env: NavigationEnv) -> Check:
    """Each action moves the robot as named: left = counter-clockwise, forward = ahead."""
    _, info = env.reset(seed=102)
    x0, y0, yaw0 = info['pose']
    moves = {}
    for action in (LEFT, FORWARD, RIGHT):
        _, _, terminated, truncated, step = env.step(action)
        x, y, yaw = step['pose']
        moves[action] = (math.hypot(x - x0, y - y0), math.remainder(yaw - yaw0, 2 * math.pi),
                         math.atan2(y - y0, x - x0) - yaw0)
        x0, y0, yaw0 = x, y, yaw
        if terminated or truncated:
            break
    ok = (len(moves) == 3 and moves[LEFT][1] > 0.05 and moves[RIGHT][1] < -0.05
          and moves[FORWARD][0] > 0.01 and abs(math.remainder(moves[FORWARD][2], 2 * math.pi))
          < 0.01 and abs(moves[FORWARD][1]) < 1e-6
          and max(moves[LEFT][0], moves[RIGHT][0]) < moves[FORWARD][0])
    measured = ', '.join(f'{name}: {moves[a][0] * 100:.1f} cm, {math.degrees(moves[a][1]):+.1f}°'
                         for a, name in ((LEFT, 'left'), (FORWARD, 'forward'), (RIGHT, 'right'))
                         if a in moves)
    return Check('Action mapping', 'left turns CCW, forward moves ahead, right turns CW',
                 measured, ok)


def check_reset(env: NavigationEnv) -> Check:
    """Check that a seed reproduces its scenario and first image and another seed differs."""
    a, info_a = env.reset(seed=205, options={'split': 'heldout'})
    env.step(FORWARD)
    b, info_b = env.reset(seed=205, options={'split': 'heldout'})
    c, _ = env.reset(seed=206, options={'split': 'heldout'})
    same = info_a['scenario']['goal'] == info_b['scenario']['goal'] and \
        info_a['scenario']['start'] == info_b['scenario']['start']
    ok = same and np.array_equal(a, b) and not np.array_equal(a, c)
    return Check('Reset reproducibility', 'same seed -> same scenario and first image',
                 f"seed 205 twice: scenario {'same' if same else 'DIFFERENT'}, image "
                 f"{'identical' if np.array_equal(a, b) else 'DIFFERENT'}; seed 206 differs: "
                 f'{not np.array_equal(a, c)}', ok)


def check_boundaries(env: NavigationEnv) -> tuple[list[Check], list[list[float]]]:
    """Check goal and collision detection by driving scripted episodes.

    Return the two checks and the wheel speeds reported at those episode boundaries.
    """
    seed, trace = drive_to_goal(env, range(101, 131))
    last = trace[-1] if trace else {}
    goal = Check('Goal detection', 'terminated=True, +5 goal reward, motors stopped',
                 f"seed {seed}: event {last.get('event')}, terminated {last.get('terminated')}, "
                 f"goal term {last.get('reward_terms', {}).get('goal')}, distance "
                 f"{last.get('distance', math.nan):.3f} m after {len(trace)} steps",
                 bool(trace) and last['terminated'] and not last['truncated']
                 and last['reward_terms']['goal'] == env.config.goal_reward)
    crash = drive_forward(env, 103)
    end = crash[-1]
    collision = Check('Collision detection', 'terminated=True, -1 collision reward',
                      f"event {end['event']} after {len(crash)} steps, terminated "
                      f"{end['terminated']}, collision term {end['reward_terms']['collision']}",
                      end['event'] == EVENT_COLLISION and end['terminated']
                      and not end['truncated'])
    # the sim's own wheel speeds in the terminal frame (stopped by the sim within the period),
    # then what the sim reports after the env's stop call at the boundary
    stops = [w for t in (last, end) if t
             for w in ((t['wheels'],) if t['terminated'] else ()) + (t['wheels_after_stop'],)]
    return [goal, collision], stops


def check_timeout(make_env: Callable[..., NavigationEnv], namespace: str) -> tuple[Check, list]:
    """Check truncation at max_episode_steps on a 5-step env attached to the same sim.

    Return the check and the wheel speeds reported after stopping the motors.
    """
    short = make_env(max_episode_steps=5, sim='attach', namespace=namespace)
    try:
        short.reset(seed=104)
        flags = [short.step(LEFT)[2:4] for _ in range(5)]
        stopped = short.stop_motors()
    finally:
        short.close()
    ok = flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])
    return Check('Timeout', 'truncated=True only, at max_episode_steps',
                 f'(terminated, truncated) per step: {flags}', ok), [stopped]


def check_checkers(env: NavigationEnv) -> list[Check]:
    """Run SB3's and Gymnasium's env checkers, one check each.

    Gymnasium's runs on a ``gymnasium.make`` env attached to the same sim (it has a spec, so the
    checker also tries the rgb_array render mode).
    """
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env as gymnasium_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    from nav_gym import ENV_ID

    made = gym.make(ENV_ID, namespace=env.namespace, sim='attach')
    out = []
    for name, checker in (('check_env() (SB3)', lambda: sb3_check(env, warn=True)),
                          ('check_env() (Gymnasium)', lambda: gymnasium_check(made.unwrapped))):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            try:
                checker()
                error = None
            except Exception as exc:  # the checkers raise AssertionError and others
                error = f'{type(exc).__name__}: {exc}'
        messages = [str(w.message) for w in caught]
        measured = error or (f'{len(messages)} warnings: {messages}' if messages
                             else 'no errors, no warnings')
        out.append(Check(name, 'no errors, no warnings', measured, not error and not messages))
    made.close()
    return out


def run_checklist(env: NavigationEnv, make_env: Callable[..., NavigationEnv]) -> list[Check]:
    """Run the workshop's validation checklist, in its order, with measured values."""
    checks = check_observation(env)
    checks.append(check_actions(env))
    checks.append(check_reset(env))
    boundary, stops = check_boundaries(env)
    checks.extend(boundary)
    timeout, more = check_timeout(make_env, env.namespace)
    checks.append(timeout)
    stops += more
    checks.append(Check('Motor stop', 'zero wheel speed at every episode boundary',
                        f'wheel speeds after the boundaries above: {stops}',
                        bool(stops) and all(s == [0.0, 0.0] for s in stops)))
    checks.extend(check_checkers(env))
    return checks


def format_checklist(checks: list[Check]) -> str:
    """Return the checklist as PASS/FAIL lines and a count."""
    width = max(len(c.name) for c in checks)
    lines = [f"{'PASS' if c.passed else 'FAIL'}  {c.name:<{width}}  {c.measured}"
             f"{'' if c.passed else f'  (expected: {c.expected})'}" for c in checks]
    failed = sum(not c.passed for c in checks)
    lines.append(f'{len(checks) - failed} passed, {failed} failed')
    return '\n'.join(lines)


def write_checklist(checks: list[Check], path: Path) -> None:
    """Write the checklist as JSON (``validation.json`` in a run directory), making its folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps([asdict(c) for c in checks], indent=1))
