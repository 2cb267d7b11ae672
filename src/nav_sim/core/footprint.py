"""Where the robot fits, and is there a way: the planner's map of a layout (no actions, no ROS).

A 1 cm grid over the arena marks the cells whose centre keeps the robot's footprint (a disc of
its radius, plus ``MARGIN``) free of walls and obstacles.  :meth:`FootprintMap.field` is the
geodesic distance to the goal over the free cells (8-connected; scipy's Dijkstra), and a
scenario is solvable when its start has a finite distance: a collision-free path for the
footprint joins start and goal (:meth:`FootprintMap.reachable`, which answers the same question
from the grid's connected regions, computed once per layout).  The scenario generator keeps
only solvable scenarios (``nav_sim.core.scenarios``); the planner
(``nav_sim.core.planner.Planner``) adds the env's actions to the same map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nav_sim.core.config import SimConfig
from nav_sim.core.geometry import ArenaGeometry, Layout, clearance_grid

GRID = 0.01             # m: the field's cell size
MARGIN = 0.002          # m: free space the planner keeps beyond the robot's radius
#: 8-connected neighbours: the field's steps, and the regions of :meth:`FootprintMap.regions`
EIGHT = np.ones((3, 3), dtype=bool)


@dataclass
class DistanceField:
    """Geodesic distance (m) to the goal region over the free cells of a layout (inf: none)."""

    half_size: float
    cell: float
    distance: np.ndarray  # (n, n), row = y index, column = x index

    def at(self, x: float, y: float) -> float:
        """Return the distance at a position: the least of the four cells around it."""
        best = math.inf
        for i, j in cells_around(x, y, self.half_size, self.cell, self.distance.shape[0]):
            best = min(best, float(self.distance[i, j]))
        return best


def cells_around(x: float, y: float, half_size: float, cell: float, n: int
                 ) -> list[tuple[int, int]]:
    """Return the (row, column) of the up to four grid cells whose centres surround (x, y)."""
    fx, fy = (x + half_size) / cell - 0.5, (y + half_size) / cell - 0.5
    i0, j0 = int(math.floor(fy)), int(math.floor(fx))
    return [(i, j) for i in (i0, i0 + 1) for j in (j0, j0 + 1) if 0 <= i < n and 0 <= j < n]


class FootprintMap:
    """The free cells of a world's layouts for the robot's footprint, and their distances."""

    def __init__(self, geometry: ArenaGeometry, config: SimConfig,
                 margin: float = MARGIN) -> None:
        """Map ``geometry`` for a footprint of the robot's radius plus ``margin``."""
        self.geometry, self.config = geometry, config
        self.footprint = geometry.robot_radius + margin
        half = geometry.half_size
        self.size = int(round(2 * half / GRID))
        self.centres = -half + (np.arange(self.size) + 0.5) * GRID
        self._free: dict[tuple, np.ndarray] = {}
        self._regions: dict[tuple, np.ndarray] = {}

    def free_cells(self, layout: Layout) -> np.ndarray:
        """Return the (n, n) grid of cell centres where the footprint is free (cached)."""
        key = (layout.split, layout.index, layout.placements)
        if key not in self._free:
            self._free[key] = clearance_grid(self.centres, self.centres, layout,
                                             self.geometry) >= self.footprint
        return self._free[key]

    def regions(self, layout: Layout) -> np.ndarray:
        """Label the 8-connected regions of free cells (0: not free; cached per layout)."""
        from scipy.ndimage import label
        key = (layout.split, layout.index, layout.placements)
        if key not in self._regions:
            self._regions[key] = label(self.free_cells(layout), structure=EIGHT)[0]
        return self._regions[key]

    def goal_cells(self, layout: Layout, goal: tuple[float, float]) -> np.ndarray:
        """Return the free cells within the success radius of the goal (the field's sources)."""
        gx, gy = goal
        c = self.centres
        near = np.hypot(c[None, :] - gx, c[:, None] - gy) <= self.config.goal_radius
        return near & self.free_cells(layout)

    def field(self, layout: Layout, goal: tuple[float, float]) -> DistanceField:
        """Return the geodesic distance to the goal region (8-connected free cells)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra
        free = self.free_cells(layout)
        n = self.size
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
        near = self.goal_cells(layout, goal)
        half = self.geometry.half_size
        if not near.any():
            return DistanceField(half, GRID, np.full((n, n), math.inf))
        distance = dijkstra(graph.tocsr(), directed=False, indices=index[near], min_only=True)
        return DistanceField(half, GRID, distance.reshape(n, n))

    def reachable(self, layout: Layout, start: tuple[float, float],
                  goal: tuple[float, float]) -> bool:
        """Tell whether a collision-free path for the footprint joins start and goal.

        The field's answer (a finite distance at ``start``), from the connected regions: a free
        cell around the start lies in a region with a free cell near the goal.
        """
        labels = self.regions(layout)
        around = {int(labels[i, j]) for i, j in cells_around(
            start[0], start[1], self.geometry.half_size, GRID, self.size)} - {0}
        if not around:
            return False
        return bool(np.isin(labels[self.goal_cells(layout, goal)], list(around)).any())
