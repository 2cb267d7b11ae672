"""Plan on the true map: is a scenario solvable, and which actions reach its goal (no ROS).

Privileged and offline: it reads a scenario's layout, start and goal (``nav_sim.scenarios``),
never an image.  Two questions, one planner:

- **Is there a way?** :meth:`Planner.field` computes the geodesic distance to the goal over a
  1 cm grid of the positions where the robot's footprint (a disc of its radius, plus
  ``MARGIN``) is free of walls and obstacles; a scenario is solvable when its start has a finite
  distance (:meth:`Planner.reachable`): a collision-free path for the footprint exists.
- **Which actions?** :meth:`Planner.plan` searches the sequences of the env's discrete actions
  (A*, the field as its heuristic) for a short one that reaches the goal within an episode's
  decisions.
  Each action is driven as the sim drives it: the wheel speeds of its twist (saturated as
  ``twist_to_wheels`` does) held for ``action_repeat`` physics steps of ``sim_dt`` on the exact
  arc (``nav_sim.sim.arc_step``), with the goal checked before a contact after every physics
  step.  The oracle baseline (:class:`nav_eval.evaluation.policies.OraclePolicy`) executes such
  plans: the ceiling of what the task's actions can achieve.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nav_sim.config import SimConfig
from nav_sim.scenarios import ArenaGeometry, Layout, clearance
from nav_sim.sim import arc_step, twist_to_wheels, wheels_to_twist

GRID = 0.01             # m: the field's cell size
MARGIN = 0.002          # m: free space the planner keeps beyond the robot's radius
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


@dataclass
class DistanceField:
    """Geodesic distance (m) to the goal region over the free cells of a layout (inf: none)."""

    half_size: float
    cell: float
    distance: np.ndarray  # (n, n), row = y index, column = x index

    def at(self, x: float, y: float) -> float:
        """Return the distance at a position: the least of the four cells around it."""
        n = self.distance.shape[0]
        fx, fy = (x + self.half_size) / self.cell - 0.5, (y + self.half_size) / self.cell - 0.5
        i0, j0 = int(math.floor(fy)), int(math.floor(fx))
        best = math.inf
        for i in (i0, i0 + 1):
            for j in (j0, j0 + 1):
                if 0 <= i < n and 0 <= j < n:
                    best = min(best, float(self.distance[i, j]))
        return best


class Planner:
    """Plans in one world (its arena) with one set of actions (the env's)."""

    def __init__(self, geometry: ArenaGeometry, config: SimConfig,
                 actions: Sequence[tuple[float, float]], margin: float = MARGIN) -> None:
        """Plan for ``actions`` given as commanded (linear m/s, angular rad/s) twists."""
        self.geometry, self.config = geometry, config
        self.motions = tuple(motion(v, w, config) for v, w in actions)
        self.footprint = geometry.robot_radius + margin
        self.longest = max(abs(m.linear) for m in self.motions) * config.ctrl_dt
        self._free: dict[tuple, np.ndarray] = {}

    # --- is there a way? -------------------------------------------------------------------
    def free_cells(self, layout: Layout) -> np.ndarray:
        """Return the (n, n) grid of cell centres where the footprint is free (cached)."""
        key = (layout.split, layout.index, layout.placements)
        if key not in self._free:
            half = self.geometry.half_size
            n = int(round(2 * half / GRID))
            centres = -half + (np.arange(n) + 0.5) * GRID
            self._free[key] = np.array([[clearance(x, y, layout, self.geometry) >= self.footprint
                                         for x in centres] for y in centres])
        return self._free[key]

    def field(self, layout: Layout, goal: tuple[float, float]) -> DistanceField:
        """Return the geodesic distance to the goal region (8-connected free cells)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra
        free = self.free_cells(layout)
        n = free.shape[0]
        half = self.geometry.half_size
        centres = -half + (np.arange(n) + 0.5) * GRID
        index = np.arange(n * n).reshape(n, n)
        rows, cols, weights = [], [], []
        i, j = np.indices((n, n))
        for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):  # each undirected edge once
            ni, nj = i + di, j + dj
            inside = (ni < n) & (nj >= 0) & (nj < n)
            both = np.zeros((n, n), dtype=bool)
            both[inside] = free[inside] & free[ni[inside], nj[inside]]
            src, dst = index[both], (ni * n + nj)[both]
            rows += [src, dst]
            cols += [dst, src]
            weights += [np.full(src.size, GRID * math.hypot(di, dj))] * 2
        graph = coo_matrix((np.concatenate(weights), (np.concatenate(rows),
                                                        np.concatenate(cols))), (n * n, n * n))
        gx, gy = goal
        near = (np.hypot(centres[None, :] - gx, centres[:, None] - gy)
                <= self.config.goal_radius) & free
        if not near.any():
            return DistanceField(half, GRID, np.full((n, n), math.inf))
        distance = dijkstra(graph.tocsr(), directed=False, indices=index[near], min_only=True)
        return DistanceField(half, GRID, distance.reshape(n, n))

    def reachable(self, layout: Layout, start: tuple[float, float],
                  goal: tuple[float, float]) -> bool:
        """Tell whether a collision-free path for the footprint joins start and goal."""
        return math.isfinite(self.field(layout, goal).at(*start))

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
                return (x, y, yaw), 'goal'
            if clearance(x, y, layout, self.geometry) < self.footprint:
                return (x, y, yaw), 'collision'
        return (x, y, yaw), 'none'

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
                if event == 'goal':
                    return [*actions, action]
                if event == 'collision' or key(end) in closed:
                    continue
                h = heuristic(end)
                if math.isfinite(h):
                    tie += 1
                    heapq.heappush(frontier, (steps + 1 + h, tie, steps + 1, end,
                                              (*actions, action)))
        return None
