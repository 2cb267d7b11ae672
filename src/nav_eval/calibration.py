"""How far a DQN's Q-values are from the returns its own policy gets (pure: numpy; no ROS).

A deterministic policy in a deterministic sim gets, from every decision of an episode that ended
(goal or collision), a return known exactly: the discounted sum of the rewards that followed, with
the run's ``gamma``.  A Q-learning network's value of the action it took estimates that return; how
far above it the value sits is the learner's *overestimation*.  DQN's target takes the maximum over
noisy estimates, so where the actions' true values are close (a turn now or a step later near the
goal, the left/right reversals of :mod:`nav_eval.anatomy`) the estimates drift up, and which action
looks best is decided by the estimation error rather than by the task.

Time-outs are left out: a truncated episode's return after the limit is unknown.  Reads the traces
``nav-eval-evaluate`` writes (``RUN/eval/traces/<set>/seed_<n>.json``: each decision's Q-values,
reward and distance to the goal after it, and the scenario's initial distance).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nav_gym import run_dir as layout

#: decisions taken closer to the goal than this (m) form the "near" band: the final approach,
#: where a turn and a step forward differ by one decision's discount
NEAR_GOAL = 0.25
TERMINATED = ('success', 'collision')


@dataclass(frozen=True)
class EpisodeValues:
    """One terminated episode: per decision, the value of the action taken and its return."""

    seed: int
    outcome: str
    q: np.ndarray  # Q(s_t, a_t) of each decision
    returns: np.ndarray  # discounted return from each decision to the episode's end
    distance: np.ndarray  # distance to the goal (m) when each decision was taken


def discounted_returns(rewards: Iterable[float], gamma: float) -> np.ndarray:
    """Return ``G_t = r_t + gamma * G_{t+1}`` for every step of a finished episode."""
    rewards = np.asarray(list(rewards), dtype=float)
    out = np.zeros_like(rewards)
    following = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        following = rewards[t] + gamma * following
        out[t] = following
    return out


def episode_values(trace: dict[str, Any], gamma: float) -> EpisodeValues | None:
    """Describe one traced episode; None for a time-out or a policy without Q-values."""
    steps = trace['steps']
    if trace['outcome'] not in TERMINATED or not steps or \
            any(s.get('q_values') is None for s in steps):
        return None
    actions = [int(s['action']) for s in steps]
    if any(not 0 <= a < len(s['q_values']) for a, s in zip(actions, steps, strict=True)):
        raise ValueError(f"seed {trace.get('seed')}: an action without its Q-value")
    q = np.array([float(s['q_values'][a]) for a, s in zip(actions, steps, strict=True)])
    before = [float(trace['scenario']['initial_distance'])] + \
        [float(s['distance']) for s in steps[:-1]]
    return EpisodeValues(seed=int(trace['seed']), outcome=trace['outcome'], q=q,
                         returns=discounted_returns((s['reward'] for s in steps), gamma),
                         distance=np.array(before))


def set_values(eval_dir: Path, set_name: str, gamma: float,
               seeds: Iterable[int] | None = None) -> list[EpisodeValues]:
    """Read the terminated episodes of one evaluated set ([] without traces).

    ``seeds``: only these (an earlier evaluation of other seeds leaves its traces in the same
    folder); an unreadable trace is left out.
    """
    return traces_values(layout.read_traces(eval_dir, set_name, seeds), gamma)


def traces_values(traces: Iterable[tuple[Path, dict[str, Any]]], gamma: float,
                  ) -> list[EpisodeValues]:
    """Describe the terminated episodes of ``(path, trace)`` pairs, by seed.

    The pairs are :func:`nav_gym.run_dir.read_traces`'s; a malformed trace is left out.
    """
    out = []
    for _, trace in traces:
        try:
            values = episode_values(trace, gamma)
        except (ValueError, KeyError, IndexError, TypeError, AttributeError):
            continue
        if values is not None:
            out.append(values)
    return sorted(out, key=lambda e: e.seed)


def summarise(episodes: Iterable[EpisodeValues]) -> dict[str, Any] | None:
    """Sum terminated episodes up; None without any.

    ``episodes`` and ``decisions`` used; means over decisions of ``q`` (the value of the action
    taken) and ``return``; ``overestimate`` = mean(Q - return), also ``near`` the goal (closer
    than :data:`NEAR_GOAL`) and ``far`` from it (None where a band has no decision).
    """
    episodes = list(episodes)
    if not episodes:
        return None
    q = np.concatenate([e.q for e in episodes])
    g = np.concatenate([e.returns for e in episodes])
    near = np.concatenate([e.distance for e in episodes]) < NEAR_GOAL

    def mean(values: np.ndarray) -> float | None:
        return float(values.mean()) if values.size else None

    return {'episodes': len(episodes), 'decisions': int(q.size), 'q': mean(q),
            'return': mean(g), 'overestimate': mean(q - g), 'near': mean((q - g)[near]),
            'far': mean((q - g)[~near])}
