"""Scenario banks and seeded scenario sampling (pure numpy, no MuJoCo, no ROS).

A *layout* places some of the world's obstacle slots in the arena.  Two banks of layouts are
generated from fixed bank seeds: a training bank and a held-out bank whose layouts all differ from
every training layout.  A *scenario* is a layout plus a robot start pose and a goal position, drawn
from ``numpy.random.default_rng([split_id, seed])`` so that the same (seed, split) always gives
the same scenario.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from nav_sim.config import SimConfig, normalise_split, validate_seed
from nav_sim.errors import ScenarioError

SPLIT_IDS = {'train': 0, 'heldout': 1}
OBSTACLE_GAP = 0.15       # free gap between obstacles and to walls (> robot diameter 0.074 m)
START_CLEARANCE = 0.05    # extra free space around the robot at its start pose
GOAL_CLEARANCE = 0.11     # free space around the goal position (m), whatever the marker's size
GOAL_MARGIN = 0.06        # ... and at least this much beyond the robot's body
MARKER_GAP = 0.01         # ... and beyond the goal marker, which never touches an obstacle
MIN_LAYOUT_DIFFERENCE = 0.1  # a held-out layout differs from every training one by > 10 cm
MAX_TRIES = 10_000


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
    """The world's arena as its MJCF defines it, read once (``nav_sim.world.World``).

    Scenario sampling needs the size, the robot's radius and the slots' footprints; the live
    view also draws the walls (boxes: centre x, y, z and half extents) and the robot's height.
    """

    half_size: float
    robot_radius: float
    shapes: tuple[ObstacleShape, ...]
    walls: tuple[tuple[float, float, float, float, float, float], ...] = ()
    robot_height: float = 0.0


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


@dataclass(frozen=True)
class Scenario:
    """Everything needed to start an episode; privileged state, never a policy input."""

    seed: int
    split: str
    layout: Layout
    start: tuple[float, float, float]
    goal: tuple[float, float]
    initial_distance: float

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready description.

        Numbers are rounded for humans; the exact values stay in the object.
        """
        return {
            'seed': self.seed, 'split': self.split, 'layout': self.layout.index,
            'start': [round(v, 4) for v in self.start],
            'goal': [round(v, 4) for v in self.goal],
            'initial_distance': round(self.initial_distance, 4),
            'obstacles': [{k: (round(v, 4) if isinstance(v, float) else v)
                           for k, v in asdict(p).items()} for p in self.layout.placements],
        }


def distance_to_obstacle(x: float, y: float, shape: ObstacleShape, place: Placement) -> float:
    """Signed 2-D distance from a point to an obstacle footprint (negative inside)."""
    dx, dy = x - place.x, y - place.y
    if shape.kind == 'cylinder':
        return math.hypot(dx, dy) - shape.half_x
    c, s = math.cos(place.yaw), math.sin(place.yaw)
    qx, qy = abs(c * dx + s * dy) - shape.half_x, abs(-s * dx + c * dy) - shape.half_y
    outside = math.hypot(max(qx, 0.0), max(qy, 0.0))
    return outside + min(max(qx, qy), 0.0)


def clearance(x: float, y: float, layout: Layout, geometry: ArenaGeometry) -> float:
    """Free distance from a point to the nearest wall or obstacle of a layout."""
    nearest = geometry.half_size - max(abs(x), abs(y))
    for place in layout.placements:
        shape = geometry.shapes[place.slot]
        nearest = min(nearest, distance_to_obstacle(x, y, shape, place))
    return nearest


def _sample_layout(rng: np.random.Generator, split: str, index: int, count: int,
                   geometry: ArenaGeometry) -> Layout:
    slots = sorted(int(s) for s in rng.choice(len(geometry.shapes), size=count, replace=False))
    for _ in range(MAX_TRIES):
        placements: list[Placement] = []
        for slot in slots:
            radius = geometry.shapes[slot].bounding_radius
            limit = geometry.half_size - radius - OBSTACLE_GAP
            x, y = (float(v) for v in rng.uniform(-limit, limit, size=2))
            yaw = float(rng.uniform(-math.pi, math.pi))
            if all(math.hypot(x - p.x, y - p.y) - radius - geometry.shapes[p.slot].bounding_radius
                   >= OBSTACLE_GAP for p in placements):
                placements.append(Placement(slot, x, y, yaw))
            else:
                break
        if len(placements) == count:
            return Layout(split, index, tuple(placements))
    raise ScenarioError(f'could not place {count} obstacles with {OBSTACLE_GAP} m gaps')


def layout_difference(a: Layout, b: Layout) -> float:
    """How far apart two layouts are: inf for different slot sets, else the largest shift (m)."""
    if [p.slot for p in a.placements] != [p.slot for p in b.placements]:
        return math.inf
    pairs = zip(a.placements, b.placements, strict=True)
    return max((math.hypot(p.x - q.x, p.y - q.y) for p, q in pairs),
               default=0.0)


def build_banks(config: SimConfig, geometry: ArenaGeometry) -> dict[str, tuple[Layout, ...]]:
    """Generate the training and held-out layout banks (deterministic for a config)."""
    count = config.num_obstacles
    if count > len(geometry.shapes):
        raise ScenarioError(f'num_obstacles={count} but the world has only '
                            f'{len(geometry.shapes)} obstacle slots')
    rng = np.random.default_rng(config.train_bank_seed)
    train = tuple(_sample_layout(rng, 'train', i, count, geometry)
                  for i in range(config.train_layouts))
    rng = np.random.default_rng(config.heldout_bank_seed)
    heldout: list[Layout] = []
    for _ in range(MAX_TRIES):
        if len(heldout) == config.heldout_layouts:
            break
        candidate = _sample_layout(rng, 'heldout', len(heldout), count, geometry)
        if all(layout_difference(candidate, t) > MIN_LAYOUT_DIFFERENCE for t in train):
            heldout.append(candidate)
    else:
        raise ScenarioError('could not build a held-out bank distinct from the training bank')
    return {'train': train, 'heldout': tuple(heldout)}


def _sample_point(rng: np.random.Generator, layout: Layout, geometry: ArenaGeometry,
                  min_clearance: float, what: str,
                  far_from: tuple[float, float] | None = None, min_distance: float = 0.0,
                  ) -> tuple[float, float]:
    limit = geometry.half_size - min_clearance
    for _ in range(MAX_TRIES):
        x, y = (float(v) for v in rng.uniform(-limit, limit, size=2))
        if clearance(x, y, layout, geometry) < min_clearance:
            continue
        if far_from is not None and math.hypot(x - far_from[0], y - far_from[1]) < min_distance:
            continue
        return x, y
    raise ScenarioError(f'no valid {what} position in layout {layout.split}/{layout.index}; '
                        'lower min_start_goal_distance or num_obstacles')


def goal_clearance(geometry: ArenaGeometry, config: SimConfig) -> float:
    """Free distance a goal position keeps from walls and obstacles.

    11 cm (the e-puck and the default 5 cm marker), more only for a bigger robot or a marker
    over 10 cm in radius: the look of the goal leaves the scenarios alone, so a marker change
    is measured on the same episodes.
    """
    return max(GOAL_CLEARANCE, geometry.robot_radius + GOAL_MARGIN,
               config.goal_marker_radius + MARKER_GAP)


def sample_scenario(seed: Any, split: str, banks: dict[str, tuple[Layout, ...]],
                    geometry: ArenaGeometry, config: SimConfig) -> Scenario:
    """Draw the scenario of (seed, split): layout, start pose and goal, all seeded."""
    seed = validate_seed(seed)
    split = normalise_split(split)
    rng = np.random.default_rng([SPLIT_IDS[split], seed])
    bank = banks[split]
    layout = bank[int(rng.integers(len(bank)))]
    start_xy = _sample_point(rng, layout, geometry, geometry.robot_radius + START_CLEARANCE,
                             'start')
    yaw = float(rng.uniform(-math.pi, math.pi))
    goal = _sample_point(rng, layout, geometry, goal_clearance(geometry, config), 'goal',
                         far_from=start_xy,
                         min_distance=config.min_start_goal_distance)
    distance = math.hypot(goal[0] - start_xy[0], goal[1] - start_xy[1])
    return Scenario(seed, split, layout, (start_xy[0], start_xy[1], yaw), goal, distance)
