"""Where an evaluated set's episodes spend their decisions (pure: numpy; no ROS).

``nav-eval-diagnose`` follows one episode through every layer; this looks across all episodes
of a set (and, in a sweep's report, across seeds) at the policy's two jobs: *finding* the goal
(how many decisions pass before the goal is first in view) and *reaching* it once seen (the
share of decisions taken with the goal in view, how many of them drive forward, and how often
the policy reverses between left and right).  A time-out whose goal came into view late is a
search failure; one that saw the goal most of the time and reversed all along is an approach
failure.  The goal is "in view" in an observation when the diagnosis's goal-marker mask
(:func:`nav_gym.policy.servo.goal_mask`) has at least ``MIN_PIXELS`` pixels: more
than the diagnosis needs to place a bearing, so that a sliver at the image edge does not count
as found.

Reads the traces ``nav-eval-evaluate`` writes: ``RUN/eval/traces/<set>/seed_<n>.json`` (the
actions and, per decision, ``goal_in_view``: whether the goal was in view in what it saw).
A trace written before that field existed needs ``seed_<n>_frames.npz`` beside it (the
observation before each decision, then the last), from which it is computed the same way.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nav_gym.env.actions import ACTION_NAMES
from nav_gym.policy.servo import goal_mask
from nav_gym.training.run_dir import frames_path
from nav_sim.core.events import OUTCOME_COLLISION, OUTCOMES
from nav_sim.core.geometry import ArenaGeometry, Layout, ObstacleShape, Placement, clearance

MIN_PIXELS = 10  # fewer green pixels than this is noise at the image edge, not the goal
HIT_DIRECTIONS = 360  # points on the robot's rim tried for where a collision touched
LEFT, FORWARD, RIGHT = ACTION_NAMES.index('left'), ACTION_NAMES.index('forward'), \
    ACTION_NAMES.index('right')


@dataclass(frozen=True)
class EpisodeAnatomy:
    """How one episode's decisions were spent."""

    seed: int
    outcome: str
    decisions: int
    first_in_view: int | None  # decisions taken before the goal was first in view; None: never
    in_view: int  # decisions taken with the goal in view
    forward_in_view: int  # of those, forward
    reversals: int  # left -> right or right -> left between consecutive decisions
    hit_bearing: float | None = None  # a collision: where the robot touched, from its heading
    hit_out_of_view: bool | None = None  # ... outside the camera's horizontal field of view


def in_view(frames: np.ndarray) -> np.ndarray:
    """Tell, per observation of a ``(T, 3, H, W)`` stack, whether the goal is in view."""
    mask = goal_mask(np.moveaxis(frames, 1, 0))  # (T, H, W) at once
    return mask.reshape(len(frames), -1).sum(axis=1) >= MIN_PIXELS


def goal_in_view(obs: np.ndarray) -> bool:
    """Tell whether the goal is in view in one ``(3, H, W)`` observation (a trace's field)."""
    return bool(in_view(obs[None])[0])


def traced_in_view(trace: dict[str, Any]) -> bool:
    """Tell whether every decision of a trace says whether the goal was in view."""
    return all('goal_in_view' in step for step in trace['steps'])


def episode_anatomy(trace: dict[str, Any], frames: np.ndarray | None = None) -> EpisodeAnatomy:
    """Describe one traced episode (``frames[i]`` is what decision ``i`` saw).

    A trace whose decisions say whether the goal was in view needs no frames.  Otherwise
    ``frames`` holds one observation per decision and the last one after it; a trace and
    frames that disagree, or neither, raise ValueError.
    """
    actions = [int(s['action']) for s in trace['steps']]
    if traced_in_view(trace):
        seen = np.array([bool(s['goal_in_view']) for s in trace['steps']], dtype=bool)
    elif frames is None:
        raise ValueError(f"seed {trace.get('seed')}: neither goal_in_view nor frames")
    elif len(frames) != len(actions) + 1:
        raise ValueError(f"seed {trace.get('seed')}: {len(frames)} observations for "
                         f'{len(actions)} decisions (expected one more)')
    else:
        seen = in_view(frames[:len(actions)])
    first = int(np.argmax(seen)) if seen.any() else None
    return EpisodeAnatomy(
        seed=int(trace['seed']), outcome=trace['outcome'], decisions=len(actions),
        first_in_view=first, in_view=int(seen.sum()),
        forward_in_view=sum(1 for a, s in zip(actions, seen, strict=True) if s and a == FORWARD),
        reversals=sum(1 for a, b in zip(actions, actions[1:], strict=False)
                      if {a, b} == {LEFT, RIGHT}))


def hit_bearing(trace: dict[str, Any], arena: dict[str, Any]) -> float | None:
    """Return where a collision episode's robot touched, relative to its heading (rad, + left).

    From the final pose and the scenario's true geometry (privileged, as evaluation records
    it): of ``HIT_DIRECTIONS`` points on the robot's rim, the one closest to a wall or an
    obstacle (``nav_sim.core.geometry.clearance``).  None for other outcomes.  ``arena`` is an
    evaluation's ``results.json`` arena (half size, robot radius, the slots' shapes).
    """
    if trace['outcome'] != OUTCOME_COLLISION or not trace['steps']:
        return None
    x, y, yaw = (float(v) for v in trace['steps'][-1]['pose'][:3])
    geometry = ArenaGeometry(float(arena['half_size']), float(arena['robot_radius']), tuple(
        ObstacleShape(s['name'], s['kind'], float(s['half_x']), float(s['half_y']))
        for s in arena['shapes']))
    layout = Layout('', 0, tuple(Placement(int(o['slot']), float(o['x']), float(o['y']),
                                           float(o.get('yaw', 0.0)))
                                 for o in trace['scenario'].get('obstacles', [])))
    angles = yaw + np.linspace(-math.pi, math.pi, HIT_DIRECTIONS, endpoint=False)
    rim = geometry.robot_radius
    gaps = [clearance(x + rim * math.cos(a), y + rim * math.sin(a), layout, geometry)
            for a in angles]
    return math.remainder(float(angles[int(np.argmin(gaps))]) - yaw, 2 * math.pi)


def traces_anatomy(traces: Iterable[tuple[Path, dict[str, Any]]],
                   arena: dict[str, Any] | None = None,
                   half_fov: float | None = None) -> list[EpisodeAnatomy]:
    """Describe episodes from their ``(path, trace)`` pairs.

    The pairs are what :func:`nav_gym.training.run_dir.read_traces` yields.

    A trace without ``goal_in_view`` reads its frames beside it; such an episode whose frames
    are missing or unreadable, or disagree with its trace, is left out.  With the evaluation's
    ``arena`` and the camera's horizontal half field of view ``half_fov`` (rad), a collision
    also says where the robot touched and whether that was out of view (:func:`hit_bearing`).
    """
    out = []
    for path, trace in traces:
        try:
            if traced_in_view(trace):
                episode = episode_anatomy(trace)
            else:
                with np.load(frames_path(path)) as data:
                    episode = episode_anatomy(trace, data['obs'])
            bearing = hit_bearing(trace, arena) if arena else None
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if bearing is not None and half_fov is not None:
            episode = dataclasses.replace(episode, hit_bearing=bearing,
                                          hit_out_of_view=abs(bearing) > half_fov)
        out.append(episode)
    return sorted(out, key=lambda e: e.seed)


def summarise(episodes: Iterable[EpisodeAnatomy]) -> dict[str, dict[str, Any]]:
    """Sum episodes up per outcome.

    Per outcome: ``episodes``; ``median_first_in_view`` (decisions before the goal was first in
    view, over the episodes that saw it) and ``never_in_view``; ``in_view_share`` (of all
    decisions); ``forward_in_view`` (forward decisions among those with the goal in view);
    ``reversals_per_100`` (left/right reversals per 100 decisions); for collisions, with
    where each touched known, ``hit_out_of_view`` (how many touched outside the camera's
    horizontal field of view; None otherwise).
    """
    by_outcome: dict[str, list[EpisodeAnatomy]] = {}
    for e in episodes:
        by_outcome.setdefault(e.outcome, []).append(e)
    out = {}
    for outcome in sorted(by_outcome, key=lambda o: (o not in OUTCOMES, OUTCOMES.index(o)
                                                     if o in OUTCOMES else 0, o)):
        group = by_outcome[outcome]
        firsts = [e.first_in_view for e in group if e.first_in_view is not None]
        decisions = sum(e.decisions for e in group)
        seen = sum(e.in_view for e in group)
        out[outcome] = {
            'episodes': len(group),
            'median_first_in_view': statistics.median(firsts) if firsts else None,
            'never_in_view': len(group) - len(firsts),
            'in_view_share': seen / decisions if decisions else None,
            'forward_in_view': sum(e.forward_in_view for e in group) / seen if seen else None,
            'reversals_per_100': 100 * sum(e.reversals for e in group) / decisions
            if decisions else None,
            'hit_out_of_view': (sum(e.hit_out_of_view for e in group)
                                if all(e.hit_out_of_view is not None for e in group)
                                and outcome == OUTCOME_COLLISION else None)}
    return out

