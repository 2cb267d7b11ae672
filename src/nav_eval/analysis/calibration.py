"""How far a DQN's Q-values are from the returns its own policy gets (pure: numpy; no ROS).

A deterministic policy in a deterministic sim gets, from every decision of an episode that ended
(goal or collision), a return known exactly: the discounted sum of the rewards that followed, with
the run's ``gamma``.  A Q-learning network's value of the action it took estimates that return; how
far above it the value sits is the learner's *overestimation*.  DQN's target takes the maximum over
noisy estimates, so where the actions' true values are close (a turn now or a step forward, the
left/right reversals of :mod:`nav_eval.analysis.anatomy`) the estimates drift up, and which
action looks best is decided by the estimation error rather than by the task.

A time-out's return after the limit is unknown, so the comparison with returns uses the episodes
that ended; a second measure needs no returns and takes every decision: the share whose Q-value
is above :func:`return_bound`, the most any episode can return from there.  Reads the traces
``nav-eval-evaluate`` writes (``RUN/eval/traces/<set>/seed_<n>.json``: each decision's Q-values,
reward and distance to the goal after it, and the scenario's initial distance).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nav_gym.training.run_dir import read_traces
from nav_sim.core.events import OUTCOME_COLLISION, OUTCOME_SUCCESS

#: decisions taken closer to the goal than this (m) form the "near" band: the final approach
NEAR_GOAL = 0.25
TERMINATED = (OUTCOME_SUCCESS, OUTCOME_COLLISION)


@dataclass(frozen=True)
class EpisodeValues:
    """One evaluated episode: per decision, the value of the action taken and what bounds it."""

    seed: int
    outcome: str
    q: np.ndarray  # Q(s_t, a_t) of each decision
    returns: np.ndarray | None  # discounted return from each decision (None: a time-out)
    distance: np.ndarray  # distance to the goal (m) when each decision was taken
    bound: np.ndarray  # the most any episode can return from each decision (return_bound)


def discounted_returns(rewards: Iterable[float], gamma: float) -> np.ndarray:
    """Return ``G_t = r_t + gamma * G_{t+1}`` for every step of a finished episode."""
    rewards = np.asarray(list(rewards), dtype=float)
    out = np.zeros_like(rewards)
    following = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        following = rewards[t] + gamma * following
        out[t] = following
    return out


def return_bound(distance: np.ndarray, reward: Any) -> np.ndarray:
    """Return the most any episode can return from decisions ``distance`` m from the goal.

    ``reward`` has the run's reward weights and ``gamma`` (a TrainConfig).  Progress pays
    ``progress_weight`` per metre, and its discounted sum over any path is at most the distance
    times the weight (summed by parts: the distance never goes below 0); the goal pays at most
    once; negative step costs and collision penalties only lower a return, positive ones are
    added at their most (every step's for ever, one collision).
    """
    most = max(reward.goal_reward, 0.0) + max(reward.collision_penalty, 0.0) + \
        max(reward.step_penalty, 0.0) / (1.0 - reward.gamma)
    return most + max(reward.progress_weight, 0.0) * np.asarray(distance, dtype=float)


def episode_values(trace: dict[str, Any], reward: Any) -> EpisodeValues | None:
    """Describe one traced episode; None for a policy without Q-values.

    ``reward``: the run's reward weights and ``gamma`` (a TrainConfig).  A time-out has no
    returns (its return after the limit is unknown).
    """
    steps = trace['steps']
    if not steps or any(s.get('q_values') is None for s in steps):
        return None
    actions = [int(s['action']) for s in steps]
    if any(not 0 <= a < len(s['q_values']) for a, s in zip(actions, steps, strict=True)):
        raise ValueError(f"seed {trace.get('seed')}: an action without its Q-value")
    q = np.array([float(s['q_values'][a]) for a, s in zip(actions, steps, strict=True)])
    before = np.array([float(trace['scenario']['initial_distance'])] +
                      [float(s['distance']) for s in steps[:-1]])
    returns = (discounted_returns((s['reward'] for s in steps), reward.gamma)
               if trace['outcome'] in TERMINATED else None)
    return EpisodeValues(seed=int(trace['seed']), outcome=trace['outcome'], q=q,
                         returns=returns, distance=before, bound=return_bound(before, reward))


def set_values(eval_dir: Path, set_name: str, reward: Any,
               seeds: Iterable[int] | None = None) -> list[EpisodeValues]:
    """Read the episodes of one evaluated set ([] without traces).

    ``reward``: the run's TrainConfig; ``seeds``: only these (an earlier evaluation of other
    seeds leaves its traces in the same folder); an unreadable trace is left out.
    """
    return traces_values(read_traces(eval_dir, set_name, seeds), reward)


def traces_values(traces: Iterable[tuple[Path, dict[str, Any]]], reward: Any,
                  ) -> list[EpisodeValues]:
    """Describe the episodes of ``(path, trace)`` pairs, by seed.

    The pairs are :func:`nav_gym.training.run_dir.read_traces`'s; a malformed trace is left out.
    """
    out = []
    for _, trace in traces:
        try:
            values = episode_values(trace, reward)
        except (ValueError, KeyError, IndexError, TypeError, AttributeError):
            continue
        if values is not None:
            out.append(values)
    return sorted(out, key=lambda e: e.seed)


def summarise(episodes: Iterable[EpisodeValues]) -> dict[str, Any] | None:
    """Sum episodes up; None without any.

    Over the episodes that ended (goal or collision): ``episodes`` and ``decisions``; means over
    their decisions of ``q`` (the value of the action taken) and ``return``; ``overestimate`` =
    mean(Q - return), also ``near`` the goal (closer than :data:`NEAR_GOAL`) and ``far`` from
    it (None where there is no such decision).  Over every decision, time-outs included:
    ``all_decisions`` and ``above_bound``, the share whose Q is above :func:`return_bound`.
    """
    episodes = list(episodes)
    if not episodes:
        return None
    ended = [e for e in episodes if e.returns is not None]

    def mean(values: np.ndarray) -> float | None:
        return float(values.mean()) if values.size else None

    def joined(name: str, group: list[EpisodeValues]) -> np.ndarray:
        return np.concatenate([getattr(e, name) for e in group]) if group else np.zeros(0)

    q, g = joined('q', ended), joined('returns', ended)
    near = joined('distance', ended) < NEAR_GOAL
    above = joined('q', episodes) > joined('bound', episodes)
    return {'episodes': len(ended), 'decisions': int(q.size), 'q': mean(q), 'return': mean(g),
            'overestimate': mean(q - g), 'near': mean((q - g)[near]),
            'far': mean((q - g)[~near]), 'all_decisions': int(above.size),
            'above_bound': mean(above.astype(float))}
