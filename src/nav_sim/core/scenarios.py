"""Scenario banks and seeded scenario sampling (pure numpy, no MuJoCo, no ROS).

A *layout* places some of the world's obstacle slots in the arena.  Two banks of layouts are
generated from fixed bank seeds: a training bank and a held-out bank whose layouts all differ from
every training layout.  A *scenario* is a layout plus a robot start pose and a goal position, drawn
from ``numpy.random.default_rng([split_id, seed])`` so that the same (seed, split) always gives
the same scenario.  Every scenario is solvable by construction: a start and goal that no
collision-free path for the robot's footprint joins (``nav_sim.core.footprint``, the planner's map)
are drawn again from the same generator, so a world where every first draw is solvable (the
default arena) keeps its scenarios bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from nav_sim.core.config import HELDOUT, TRAIN, SimConfig, normalise_split, validate_seed
from nav_sim.core.footprint import FootprintMap
from nav_sim.core.geometry import ArenaGeometry, Layout, Placement, clearance, distance_to_wall
from nav_sim.errors import ScenarioError

#: the scenario the demos and nav-gym-episode show unless told otherwise: the first seed of the
#: evaluation's training bank (``nav_eval.seeds.TRAIN_BANK``)
DEMO_SEED = 101
SPLIT_IDS = {TRAIN: 0, HELDOUT: 1}
START_CLEARANCE = 0.05    # extra free space around the robot at its start pose
GOAL_CLEARANCE = 0.11     # free space around the goal position (m), whatever the marker's size
GOAL_MARGIN = 0.06        # ... and at least this much beyond the robot's body
MARKER_GAP = 0.01         # ... and beyond the goal marker, which never touches an obstacle
MIN_LAYOUT_DIFFERENCE = 0.1  # a held-out layout differs from every training one by > 10 cm
MAX_TRIES = 10_000


@dataclass(frozen=True)
class Scenario:
    """Everything needed to start an episode; privileged state, never a policy input."""

    seed: int
    split: str
    layout: Layout
    start: tuple[float, float, float]
    goal: tuple[float, float]
    initial_distance: float
    look: Any = None  # the drawn look (``nav_sim.core.looks.Look``) when looks are randomised

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
            **({} if self.look is None else {'look': self.look.to_dict()}),
        }


def _sample_layout(rng: np.random.Generator, split: str, index: int, count: int,
                   geometry: ArenaGeometry, gap: float) -> Layout:
    slots = sorted(int(s) for s in rng.choice(len(geometry.shapes), size=count, replace=False))
    for _ in range(MAX_TRIES):
        placements: list[Placement] = []
        for slot in slots:
            radius = geometry.shapes[slot].bounding_radius
            limit = geometry.half_size - radius - gap
            x, y = (float(v) for v in rng.uniform(-limit, limit, size=2))
            yaw = float(rng.uniform(-math.pi, math.pi))
            if all(math.hypot(x - p.x, y - p.y) - radius - geometry.shapes[p.slot].bounding_radius
                   >= gap for p in placements) and all(
                    distance_to_wall(x, y, wall) - radius >= gap
                    for wall in geometry.interior_walls):
                placements.append(Placement(slot, x, y, yaw))
            else:
                break
        if len(placements) == count:
            return Layout(split, index, tuple(placements))
    raise ScenarioError(f'could not place {count} obstacles with {gap} m gaps in the arena; '
                        'lower num_obstacles or obstacle_gap')


def layout_difference(a: Layout, b: Layout) -> float:
    """How far apart two layouts are: inf for different slot sets, else the largest shift (m)."""
    if [p.slot for p in a.placements] != [p.slot for p in b.placements]:
        return math.inf
    pairs = zip(a.placements, b.placements, strict=True)
    return max((math.hypot(p.x - q.x, p.y - q.y) for p, q in pairs),
               default=0.0)


def build_banks(config: SimConfig, geometry: ArenaGeometry) -> dict[str, tuple[Layout, ...]]:
    """Generate the training and held-out layout banks (deterministic for a config).

    A ScenarioError names the world: the settings, not the file, left no room for the banks.
    """
    try:
        return _build_banks(config, geometry)
    except ScenarioError as exc:
        raise ScenarioError(f'world {config.world}: {exc}') from None


def _build_banks(config: SimConfig, geometry: ArenaGeometry) -> dict[str, tuple[Layout, ...]]:
    count = config.num_obstacles
    if count > len(geometry.shapes):
        raise ScenarioError(f'num_obstacles={count} but the world has only '
                            f'{len(geometry.shapes)} obstacle slots')
    gap = config.obstacle_gap
    rng = np.random.default_rng(config.train_bank_seed)
    train = tuple(_sample_layout(rng, TRAIN, i, count, geometry, gap)
                  for i in range(config.train_layouts))
    rng = np.random.default_rng(config.heldout_bank_seed)
    heldout: list[Layout] = []
    for _ in range(MAX_TRIES):
        if len(heldout) == config.heldout_layouts:
            break
        candidate = _sample_layout(rng, HELDOUT, len(heldout), count, geometry, gap)
        if all(layout_difference(candidate, t) > MIN_LAYOUT_DIFFERENCE for t in train):
            heldout.append(candidate)
    else:
        raise ScenarioError('could not build a held-out bank distinct from the training bank')
    return {TRAIN: train, HELDOUT: tuple(heldout)}


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
    paths = footprint_map(geometry, config)
    for _ in range(MAX_TRIES):
        start_xy = _sample_point(rng, layout, geometry, geometry.robot_radius + START_CLEARANCE,
                                 'start')
        yaw = float(rng.uniform(-math.pi, math.pi))
        goal = _sample_point(rng, layout, geometry, goal_clearance(geometry, config), 'goal',
                             far_from=start_xy,
                             min_distance=config.min_start_goal_distance)
        if paths.reachable(layout, start_xy, goal):  # solvable: else draw both again
            distance = math.hypot(goal[0] - start_xy[0], goal[1] - start_xy[1])
            return Scenario(seed, split, layout, (start_xy[0], start_xy[1], yaw), goal, distance)
    raise ScenarioError(f'no solvable scenario in layout {layout.split}/{layout.index}: no '
                        'collision-free path joins a start and a goal; lower num_obstacles or '
                        'obstacle_gap, or open the walls')


_MAPS: dict[tuple[ArenaGeometry, SimConfig], FootprintMap] = {}


def footprint_map(geometry: ArenaGeometry, config: SimConfig) -> FootprintMap:
    """Return the footprint map the generator checks a world's scenarios on (one per world)."""
    key = (geometry, config)
    if key not in _MAPS:
        if len(_MAPS) >= 8:  # a process plays a few worlds: keep the recent ones
            _MAPS.pop(next(iter(_MAPS)))
        _MAPS[key] = FootprintMap(geometry, config)
    return _MAPS[key]
