from __future__ import annotations

import math

import pytest

from nav_sim.core.config import SimConfig
from nav_sim.core.geometry import clearance, distance_to_obstacle
from nav_sim.core.scenarios import (
    MIN_LAYOUT_DIFFERENCE,
    goal_clearance,
    layout_difference,
    sample_scenario,
)
from nav_sim.errors import ScenarioError


def test_same_seed_same_scenario_different_seed_different(sim):
    a = sample_scenario(101, 'train', sim.banks, sim.world.geometry, sim.config)
    b = sample_scenario(101, 'train', sim.banks, sim.world.geometry, sim.config)
    c = sample_scenario(102, 'train', sim.banks, sim.world.geometry, sim.config)
    assert a == b
    assert (a.start, a.goal) != (c.start, c.goal)


def test_splits_draw_from_their_own_bank(sim):
    for seed in range(101, 111):
        s = sample_scenario(seed, 'train', sim.banks, sim.world.geometry, sim.config)
        assert s.layout in sim.banks['train']
    for seed in range(201, 211):
        s = sample_scenario(seed, 'heldout', sim.banks, sim.world.geometry, sim.config)
        assert s.layout in sim.banks['heldout']


def test_heldout_layouts_differ_from_every_training_layout(sim):
    assert len(sim.banks['train']) == sim.config.train_layouts
    assert len(sim.banks['heldout']) == sim.config.heldout_layouts
    for held in sim.banks['heldout']:
        for train in sim.banks['train']:
            assert layout_difference(held, train) > MIN_LAYOUT_DIFFERENCE


def test_scenarios_respect_constraints(sim):
    geometry, cfg = sim.world.geometry, sim.config
    for split in ('train', 'heldout'):
        for seed in range(200):
            s = sample_scenario(seed, split, sim.banks, geometry, cfg)
            assert clearance(s.start[0], s.start[1], s.layout, geometry) > geometry.robot_radius
            assert clearance(s.goal[0], s.goal[1], s.layout, geometry) > geometry.robot_radius
            assert s.initial_distance >= cfg.min_start_goal_distance
            assert math.isclose(s.initial_distance, math.dist(s.start[:2], s.goal))


@pytest.mark.parametrize('marker_radius, same_goals', [(0.1, True), (0.2, False)])
def test_the_goal_marker_never_touches_an_obstacle_and_up_to_10_cm_keeps_the_scenarios(
        sim, marker_radius, same_goals):
    geometry = sim.world.geometry
    config = SimConfig(goal_marker_radius=marker_radius)
    goals, default_goals = [], []
    for split, seeds in (('train', range(101, 151)), ('heldout', range(201, 251))):
        for seed in seeds:
            s = sample_scenario(seed, split, sim.banks, geometry, config)
            default = sample_scenario(seed, split, sim.banks, geometry, sim.config)
            assert clearance(s.goal[0], s.goal[1], s.layout, geometry) > marker_radius
            assert (s.start, s.layout) == (default.start, default.layout)
            goals.append(s.goal)
            default_goals.append(default.goal)
    # the look of the goal leaves the episodes alone until the marker needs more room
    assert (goals == default_goals) is same_goals


def test_the_goal_keeps_11_cm_free_as_it_always_has_for_the_e_puck(sim):
    geometry = sim.world.geometry
    # before markers could grow: max(robot radius, 5 cm marker) + 6 cm
    assert goal_clearance(geometry, sim.config) == pytest.approx(
        max(geometry.robot_radius, 0.05) + 0.06)
    assert goal_clearance(geometry, SimConfig(goal_marker_radius=0.1)) == pytest.approx(0.11)
    assert goal_clearance(geometry, SimConfig(goal_marker_radius=0.2)) == pytest.approx(0.21)


def test_layout_obstacles_keep_a_gap_a_robot_fits_through(sim):
    geometry = sim.world.geometry
    for layout in sim.banks['train'] + sim.banks['heldout']:
        assert len(layout.placements) == sim.config.num_obstacles
        for i, p in enumerate(layout.placements):
            r = geometry.shapes[p.slot].bounding_radius
            assert geometry.half_size - max(abs(p.x), abs(p.y)) - r > 2 * geometry.robot_radius
            for q in layout.placements[i + 1:]:
                r_q = geometry.shapes[q.slot].bounding_radius
                gap = math.hypot(p.x - q.x, p.y - q.y) - r - r_q
                assert gap > 2 * geometry.robot_radius


def test_box_distance_is_signed(sim):
    layout = sim.banks['train'][0]
    place = layout.placements[0]
    shape = sim.world.geometry.shapes[place.slot]
    assert distance_to_obstacle(place.x, place.y, shape, place) < 0
    assert distance_to_obstacle(place.x + 0.5, place.y + 0.5, shape, place) > 0.2


@pytest.mark.parametrize('seed, split', [(-1, 'train'), (1.5, 'train'), ('7', 'train'),
                                         (True, 'train'), (3, 'validation'), (3, '')])
def test_bad_requests_are_rejected_clearly(sim, seed, split):
    with pytest.raises(ScenarioError, match='seed|split'):
        sample_scenario(seed, split, sim.banks, sim.world.geometry, sim.config)


def test_split_aliases(sim):
    a = sample_scenario(5, 'held-out', sim.banks, sim.world.geometry, sim.config)
    b = sample_scenario(5, 'heldout', sim.banks, sim.world.geometry, sim.config)
    assert a == b and a.split == 'heldout'


def test_config_rejects_nonsense():
    from nav_sim.errors import ConfigError
    with pytest.raises(ConfigError, match='sim_dt'):
        SimConfig(sim_dt=float('nan'))
    with pytest.raises(ConfigError, match='unknown'):
        SimConfig.from_dict({'fov': 90})
    assert SimConfig.from_dict({'action_repeat': '4'}).action_repeat == 4
