"""The arena in the plane: its walls, obstacle footprints and free distance (pure numpy).

What the scenarios, the footprint map and the planner know of a world, read once from its MJCF
(``nav_sim.core.world.World``): the square inside the outer walls, the interior walls (axis-aligned
boxes, e.g. between rooms), the obstacle slots' footprints and the robot's radius.
:func:`clearance` is the free distance from a point to the nearest wall or obstacle, and
:func:`clearance_grid` the same numbers for a grid of points at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

_INSIDE = 1e-9  # m: a wall whose footprint reaches this far into the square is interior


class Box(NamedTuple):
    """An axis-aligned wall box: centre x, y, z and half extents, in metres.

    A tuple (it indexes, compares and serialises as one) whose fields have names.
    """

    x: float
    y: float
    z: float
    half_x: float
    half_y: float
    half_z: float


@dataclass(frozen=True)
class ObstacleShape:
    """Footprint of one obstacle slot of the world: a box (half extents) or a cylinder."""

    name: str
    kind: str
    half_x: float
    half_y: float
    half_z: float = 0.0  # half its height (the live view draws it; sampling needs none)

    @property
    def bounding_radius(self) -> float:
        """Return the radius of the circle around the slot centre that covers the footprint."""
        return self.half_x if self.kind == 'cylinder' else math.hypot(self.half_x, self.half_y)


@dataclass(frozen=True)
class ArenaGeometry:
    """The world's arena as its MJCF defines it, read once (``nav_sim.core.world.World``).

    Scenario sampling needs the size, the robot's radius, the slots' footprints and the
    interior walls; the live view also draws every wall (boxes: centre x, y, z and half
    extents) and the robot's height.
    """

    half_size: float
    robot_radius: float
    shapes: tuple[ObstacleShape, ...]
    walls: tuple[Box, ...] = ()
    robot_height: float = 0.0

    @cached_property
    def interior_walls(self) -> tuple[Box, ...]:
        """Return the walls inside the square of the outer walls (e.g. between rooms)."""
        inner = self.half_size - _INSIDE
        return tuple(w for w in self.walls
                     if abs(w[0]) - w[3] < inner and abs(w[1]) - w[4] < inner)


@dataclass(frozen=True)
class Placement:
    """One obstacle slot placed at (x, y) with heading yaw."""

    slot: int
    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class Layout:
    """An obstacle layout of a bank."""

    split: str
    index: int
    placements: tuple[Placement, ...]


def distance_to_obstacle(x: float, y: float, shape: ObstacleShape, place: Placement) -> float:
    """Signed 2-D distance from a point to an obstacle footprint (negative inside)."""
    dx, dy = x - place.x, y - place.y
    if shape.kind == 'cylinder':
        return math.hypot(dx, dy) - shape.half_x
    c, s = math.cos(place.yaw), math.sin(place.yaw)
    qx, qy = abs(c * dx + s * dy) - shape.half_x, abs(-s * dx + c * dy) - shape.half_y
    outside = math.hypot(max(qx, 0.0), max(qy, 0.0))
    return outside + min(max(qx, qy), 0.0)


def distance_to_wall(x: float, y: float, wall: Box) -> float:
    """Signed 2-D distance from a point to an axis-aligned wall's footprint (negative inside)."""
    qx, qy = abs(x - wall[0]) - wall[3], abs(y - wall[1]) - wall[4]
    return math.hypot(max(qx, 0.0), max(qy, 0.0)) + min(max(qx, qy), 0.0)


def clearance(x: float, y: float, layout: Layout, geometry: ArenaGeometry) -> float:
    """Free distance from a point to the nearest wall or obstacle of a layout."""
    nearest = geometry.half_size - max(abs(x), abs(y))
    for wall in geometry.interior_walls:
        nearest = min(nearest, distance_to_wall(x, y, wall))
    for place in layout.placements:
        shape = geometry.shapes[place.slot]
        nearest = min(nearest, distance_to_obstacle(x, y, shape, place))
    return nearest


def clearance_grid(xs: np.ndarray, ys: np.ndarray, layout: Layout,
                   geometry: ArenaGeometry) -> np.ndarray:
    """Return :func:`clearance` at every (x, y) of a grid: shape (len(ys), len(xs)).

    The same formulas, evaluated with numpy over all points at once (row = y, column = x).
    """
    x, y = np.meshgrid(np.asarray(xs, dtype=float), np.asarray(ys, dtype=float))
    nearest = geometry.half_size - np.maximum(np.abs(x), np.abs(y))

    def box(qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
        outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
        return outside + np.minimum(np.maximum(qx, qy), 0.0)

    for wall in geometry.interior_walls:
        nearest = np.minimum(nearest, box(np.abs(x - wall[0]) - wall[3],
                                          np.abs(y - wall[1]) - wall[4]))
    for place in layout.placements:
        shape = geometry.shapes[place.slot]
        dx, dy = x - place.x, y - place.y
        if shape.kind == 'cylinder':
            distance = np.hypot(dx, dy) - shape.half_x
        else:
            c, s = math.cos(place.yaw), math.sin(place.yaw)
            distance = box(np.abs(c * dx + s * dy) - shape.half_x,
                           np.abs(-s * dx + c * dy) - shape.half_y)
        nearest = np.minimum(nearest, distance)
    return nearest
