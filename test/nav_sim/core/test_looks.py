"""Seeded visual randomisation: off by default, seeded, disjoint palettes, the goal's hue kept."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator

import mujoco
import numpy as np
import pytest

from nav_gym.policy.servo import goal_mask
from nav_sim.core.config import SimConfig
from nav_sim.core.looks import BANDS, bands_of, draw_look, green_excess, hue_band
from nav_sim.core.sim import NavSim

SEEDS = {'train': range(101, 111), 'heldout': range(201, 211)}


@pytest.fixture(scope='module')
def looks() -> Iterator[NavSim]:
    core = NavSim(SimConfig(randomize_look=True))
    yield core
    core.close()


def first_images(sim: NavSim) -> list[bytes]:
    out = []
    for split, seeds in SEEDS.items():
        for seed in seeds:
            sim.reset(seed, split)
            out.append(sim.render().tobytes())
    return out


def test_off_by_default_the_scenario_has_no_look(sim):
    assert SimConfig().randomize_look is False
    assert 'look' not in sim.reset(101, 'train').to_dict()


def test_one_seed_gives_the_same_bytes_and_another_seed_another_look(looks):
    again = NavSim(SimConfig(randomize_look=True))
    try:
        assert first_images(again) == first_images(looks)
    finally:
        again.close()
    a, b = looks.reset(101, 'train').to_dict()['look'], looks.reset(102, 'train').to_dict()['look']
    assert a != b
    assert draw_look(101, 'train') != draw_look(101, 'heldout')


def test_a_look_leaves_layouts_starts_and_goals_alone(sim, looks):
    for split, seeds in SEEDS.items():
        for seed in seeds:
            plain, drawn = sim.reset(seed, split), looks.reset(seed, split)
            assert dataclasses.replace(drawn, look=None) == plain
            assert drawn.to_dict()['look'] == drawn.look.to_dict()


def test_the_plain_look_comes_back_exactly(sim, looks):
    def state(model: mujoco.MjModel) -> list[np.ndarray]:
        return [model.mat_rgba.copy(), model.geom_rgba.copy(), model.light_dir.copy(),
                model.light_diffuse.copy(), model.vis.headlight.ambient.copy()]
    plain = state(sim.world.model)  # a sim without randomisation never changes its look
    looks.reset(101, 'train')
    assert not all(np.array_equal(a, b) for a, b in zip(state(looks.world.model), plain,
                                                         strict=True))
    looks.world.apply_look(None)
    assert all(np.array_equal(a, b) for a, b in zip(state(looks.world.model), plain,
                                                     strict=True))
    looks.reset(101, 'train')  # and the drawn look again


def test_training_and_heldout_palettes_are_disjoint():
    assert set(bands_of('train')).isdisjoint(bands_of('heldout'))
    assert sorted(bands_of('train') + bands_of('heldout')) == list(range(BANDS))
    seen = {'train': set(), 'heldout': set()}
    for split in seen:
        for seed in range(500):
            look = draw_look(seed, split)
            for colour in (look.floor, look.walls, look.obstacles):
                band = hue_band(colour)
                assert band in bands_of(split), (split, seed, colour)
                seen[split].add(band)
    assert seen['train'] == set(bands_of('train'))  # every band of the palette is used
    assert seen['heldout'] == set(bands_of('heldout'))


def test_no_drawn_colour_takes_the_goals_hue_and_the_light_stays_in_range():
    for split in ('train', 'heldout'):
        for seed in range(1000):
            look = draw_look(seed, split)
            for colour in (look.floor, look.walls, look.obstacles):
                assert green_excess(colour) <= 1e-12, (split, seed, colour)
            assert math.isclose(np.linalg.norm(look.light_dir), 1.0)
            assert look.light_dir[2] < -0.5  # from above: 35 degrees or more


@pytest.mark.parametrize('world', ['arena.xml', 'clutter.xml', 'rooms.xml'])
def test_goal_pixels_appear_only_on_the_goal_in_every_look(world):
    """Render 40 looks facing the goal: the goal detector fires on the goal's pixels only.

    A segmentation render of the same camera says where the goal is; the detector
    (``goal_mask``) must find it whenever it shows, and nothing else.
    """
    sim = NavSim(SimConfig.from_dict({'world': world, 'randomize_look': True}))
    world_ = sim.world
    segment = mujoco.Renderer(world_.model, sim.config.camera_height, sim.config.camera_width)
    segment.enable_segmentation_rendering()
    goal_geom = mujoco.mj_name2id(world_.model, mujoco.mjtObj.mjOBJ_GEOM, 'goal')
    goal_colour = world_.model.mat_rgba[world_.model.geom_matid[goal_geom]].copy()
    shown = 0
    try:
        for split, first in (('train', 101), ('heldout', 201)):
            for seed in range(first, first + 20):
                scenario = sim.reset(seed, split)
                (x, y, _), (gx, gy) = scenario.start, scenario.goal
                world_.set_robot_pose(x, y, math.atan2(gy - y, gx - x))  # facing the goal
                mujoco.mj_forward(world_.model, world_.data)
                rgb = sim.render()
                segment.update_scene(world_.data, camera=world_.camera_id)
                seg = segment.render()
                is_goal = (seg[..., 0] == goal_geom) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)
                detected = goal_mask(rgb.transpose(2, 0, 1))
                assert not (detected & ~is_goal).any(), (world, split, seed)
                if is_goal.sum() >= 10:
                    shown += 1
                    assert detected[is_goal].mean() > 0.9, (world, split, seed)
        assert np.array_equal(world_.model.mat_rgba[world_.model.geom_matid[goal_geom]],
                              goal_colour)
        assert shown >= 10  # the goal was in view often enough to test its detection
    finally:
        segment.close()
        sim.close()
