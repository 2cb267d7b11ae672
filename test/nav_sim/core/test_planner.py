"""The planner on the true map: solvability of a scenario, and action plans the sim executes."""

from __future__ import annotations

import math

import pytest

from nav_gym.env.actions import action_twists
from nav_gym.env.config import EnvConfig
from nav_sim.core.config import SimConfig
from nav_sim.core.geometry import Layout, Placement
from nav_sim.core.kinematics import twist_to_wheels
from nav_sim.core.planner import Planner, motion
from nav_sim.core.sim import NavSim


@pytest.fixture(scope='module')
def planner(sim) -> Planner:
    return Planner(sim.world.geometry, sim.config, action_twists(EnvConfig()))


def test_a_driven_action_ends_where_the_sim_puts_the_robot(sim, planner):
    scenario = sim.reset(101, 'train')
    pose = sim.pose
    for action in (1, 0, 2, 1):
        predicted, event = planner.drive(pose, action, scenario.layout, scenario.goal)
        result = sim.step(twist_to_wheels(*action_twists(EnvConfig())[action], sim.config))
        assert event == result.event == 'none'
        assert predicted[:2] == pytest.approx(result.pose[:2], abs=1e-12)
        assert math.remainder(predicted[2] - result.pose[2], 2 * math.pi) == pytest.approx(
            0.0, abs=1e-12)
        pose = predicted


def test_the_motions_are_the_twists_the_sim_applies(sim, planner):
    forward = planner.motions[1]
    assert (forward.linear, forward.angular) == (EnvConfig().forward_speed, 0.0)
    saturated = motion(10.0, 0.0, sim.config)  # far beyond the wheels' limit
    assert saturated.linear == pytest.approx(sim.config.max_wheel_speed *
                                             sim.config.wheel_radius)


@pytest.mark.parametrize(('split', 'seeds'), [('train', range(101, 106)),
                                              ('heldout', range(201, 206))])
def test_plans_reach_the_goal_in_the_sim(sim, planner, split, seeds):
    for seed in seeds:
        scenario = sim.reset(seed, split)
        plan = planner.plan(scenario.layout, sim.pose, scenario.goal, 100)
        assert plan is not None and 0 < len(plan) <= 100, seed
        for action in plan:
            result = sim.step(twist_to_wheels(*action_twists(EnvConfig())[action], sim.config))
            if result.done:
                break
        assert result.event == 'goal' and result.episode_step == len(plan), seed


@pytest.mark.parametrize('world', ['clutter.xml', 'rooms.xml'])
def test_plans_reach_the_goal_in_the_other_worlds(world):
    """The oracle's plans in each world, within the world's own episode limit."""
    env_config = EnvConfig(sim_params={'world': world})
    limit = env_config.max_episode_steps
    core = NavSim(SimConfig.from_dict({'world': world}))
    try:
        world_planner = Planner(core.world.geometry, core.config, action_twists(env_config))
        for split, seed in (('train', 101), ('heldout', 201), ('heldout', 202)):
            scenario = core.reset(seed, split)
            plan = world_planner.plan(scenario.layout, core.pose, scenario.goal, limit)
            assert plan is not None and 0 < len(plan) <= limit, (split, seed)
            for action in plan:
                result = core.step(twist_to_wheels(*action_twists(env_config)[action],
                                                   core.config))
                if result.done:
                    break
            assert result.event == 'goal' and result.episode_step == len(plan), (split, seed)
    finally:
        core.close()


def test_a_goal_walled_in_by_obstacles_is_unreachable(sim, planner):
    """Two boxes close a corner of the arena around the goal: no way in, no plan."""
    shapes = sim.world.geometry.shapes
    assert (shapes[1].half_x, shapes[1].half_y, shapes[4].half_x, shapes[4].half_y) == (
        0.15, 0.05, 0.12, 0.06)  # obstacle_1 spans x 0.70..1.00; obstacle_4 y 0.76..1.00
    closed = Layout('train', -1, (Placement(1, 0.85, 0.72, 0.0),
                                  Placement(4, 0.72, 0.88, math.pi / 2)))
    start, goal = (-0.7, -0.7, 0.0), (0.9, 0.9)
    assert not planner.reachable(closed, start[:2], goal)
    assert planner.plan(closed, start, goal, 100) is None
    opened = Layout('train', -2, closed.placements[:1])  # one box only: now there is a way
    assert planner.reachable(opened, start[:2], goal)
    assert planner.plan(opened, start, goal, 100)


def test_a_plan_keeps_to_the_episode_limit(sim, planner):
    scenario = sim.reset(204, 'heldout')
    plan = planner.plan(scenario.layout, sim.pose, scenario.goal, 100)
    assert len(plan) <= 100
    assert len(planner.plan(scenario.layout, sim.pose, scenario.goal, len(plan))) <= len(plan)
    # three decisions drive at most 3 x 6.1 cm: never to a goal 0.6 m away or more
    assert scenario.initial_distance >= 0.6
    assert planner.plan(scenario.layout, sim.pose, scenario.goal, 3) is None
