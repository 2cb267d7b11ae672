"""Plan on the true map: is a scenario solvable, and which actions reach its goal (no ROS).

Privileged and offline: it reads a scenario's layout, start and goal (``nav_sim.core.scenarios``),
never an image, and it loads no MuJoCo.  Two questions, one planner:

- **Is there a way?** :meth:`Planner.field` computes the geodesic distance to the goal over a
  1 cm grid of the positions where the robot's footprint (a disc of its radius, plus
  ``MARGIN``) is free of walls and obstacles; a scenario is solvable when its start has a finite
  distance (:meth:`Planner.reachable`): a collision-free path for the footprint exists.  This
  part needs no actions: it is :class:`nav_sim.core.footprint.FootprintMap`, with which the
  scenario generator keeps only solvable scenarios.
- **Which actions?** :meth:`Planner.plan` searches the sequences of the env's discrete actions
  (A*, the field as its heuristic) for a short one that reaches the goal within an episode's
  decisions.
  Each action is driven as the sim drives it: the wheel speeds of its twist (saturated as
  ``twist_to_wheels`` does) held for ``action_repeat`` physics steps of ``sim_dt`` on the exact
  arc (``nav_sim.core.kinematics.arc_step``), with the goal checked before a contact after every
  physics step.  The oracle baseline (:class:`nav_eval.evaluation.policies.OraclePolicy`)
  executes such plans: the ceiling of what the task's actions can achieve.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass

from nav_sim.core.config import SimConfig
from nav_sim.core.events import EVENT_COLLISION, EVENT_GOAL, EVENT_NONE
from nav_sim.core.footprint import MARGIN, FootprintMap
from nav_sim.core.geometry import ArenaGeometry, Layout, clearance
from nav_sim.core.kinematics import arc_step, twist_to_wheels, wheels_to_twist

POSE_BIN = 0.01         # m: positions closer than this are one search state ...
HEADING_BINS = 72       # ... and headings within 5 degrees
MAX_EXPANSIONS = 60_000  # search states one plan may expand before it gives up


@dataclass(frozen=True)
class Motion:
    """One action as the sim drives it: the body twist after wheel saturation."""

    linear: float
    angular: float

    @property
    def straight(self) -> bool:
        """Tell whether the motion is a straight line (the sim's test)."""
        return abs(self.angular) < 1e-9

    @property
    def radius(self) -> float:
        """Return the arc's radius (0 for a straight line, as the sim sets it)."""
        return 0.0 if self.straight else self.linear / self.angular


def motion(linear: float, angular: float, config: SimConfig) -> Motion:
    """Return the motion of a commanded twist: through the wheels, as the sim applies it."""
    wheels = twist_to_wheels(linear, angular, config)
    return Motion(*wheels_to_twist(wheels.left, wheels.right, config))


class Planner(FootprintMap):
    """Plans in one world (its arena) with one set of actions (the env's).

    The footprint map (free cells, field, reachable) is :class:`FootprintMap`'s, which the
    scenario generator uses without actions.
    """

    def __init__(self, geometry: ArenaGeometry, config: SimConfig,
                 actions: Sequence[tuple[float, float]], margin: float = MARGIN) -> None:
        """Plan for ``actions`` given as commanded (linear m/s, angular rad/s) twists."""
        super().__init__(geometry, config, margin)
        self.motions = tuple(motion(v, w, config) for v, w in actions)
        self.longest = max(abs(m.linear) for m in self.motions) * config.ctrl_dt

    # --- which actions? -------------------------------------------------------------------
    def drive(self, pose: tuple[float, float, float], action: int, layout: Layout,
              goal: tuple[float, float]) -> tuple[tuple[float, float, float], str]:
        """Drive one action from ``pose`` as the sim would; return the end pose and the event.

        The event is ``goal`` or ``collision`` (the period ends early there) or ``none``.
        """
        m, cfg = self.motions[action], self.config
        x, y, yaw = pose
        gx, gy = goal
        for _ in range(cfg.action_repeat):
            x, y, yaw = arc_step(x, y, yaw, m.linear, m.angular, m.radius, m.straight,
                                 cfg.sim_dt)
            if math.hypot(gx - x, gy - y) <= cfg.goal_radius:
                return (x, y, yaw), EVENT_GOAL
            if clearance(x, y, layout, self.geometry) < self.footprint:
                return (x, y, yaw), EVENT_COLLISION
        return (x, y, yaw), EVENT_NONE

    def plan(self, layout: Layout, pose: tuple[float, float, float], goal: tuple[float, float],
             max_steps: int) -> list[int] | None:
        """Return actions that reach the goal within ``max_steps``, or None.

        A* over poses (merged within ``POSE_BIN`` and ``360 / HEADING_BINS`` degrees), each
        action one step, the field's distance over the longest step as the heuristic: a short
        sequence, not always the shortest (merging poses and the grid's distances can cost a
        step).  None when no sequence is found within ``MAX_EXPANSIONS`` states.
        """
        field = self.field(layout, goal)
        if not math.isfinite(field.at(pose[0], pose[1])):
            return None

        def key(p: tuple[float, float, float]) -> tuple[int, int, int]:
            return (round(p[0] / POSE_BIN), round(p[1] / POSE_BIN),
                    round(p[2] / (2 * math.pi / HEADING_BINS)) % HEADING_BINS)

        def heuristic(p: tuple[float, float, float]) -> float:
            return field.at(p[0], p[1]) / self.longest

        tie = 0
        frontier = [(heuristic(pose), tie, 0, pose, ())]
        closed: set[tuple[int, int, int]] = set()
        while frontier and len(closed) < MAX_EXPANSIONS:
            _, _, steps, current, actions = heapq.heappop(frontier)
            state = key(current)
            if state in closed:
                continue
            closed.add(state)
            if steps >= max_steps:
                continue
            for action in range(len(self.motions)):
                end, event = self.drive(current, action, layout, goal)
                if event == EVENT_GOAL:
                    return [*actions, action]
                if event == EVENT_COLLISION or key(end) in closed:
                    continue
                h = heuristic(end)
                if math.isfinite(h):
                    tie += 1
                    heapq.heappush(frontier, (steps + 1 + h, tie, steps + 1, end,
                                              (*actions, action)))
        return None
