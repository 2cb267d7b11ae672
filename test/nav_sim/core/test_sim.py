from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from nav_sim.core.config import SimConfig
from nav_sim.core.events import EVENT_COLLISION, EVENT_GOAL, EVENT_NONE
from nav_sim.core.kinematics import WheelCommand, twist_to_wheels, wheels_to_twist
from nav_sim.core.sim import NavSim
from nav_sim.errors import EpisodeNotStartedError

CFG = SimConfig()
FORWARD = twist_to_wheels(0.12, 0.0, CFG)
LEFT = twist_to_wheels(0.0, 1.5, CFG)
RIGHT = twist_to_wheels(0.0, -1.5, CFG)


def place(sim: NavSim, x: float, y: float, yaw: float, goal: tuple[float, float]) -> None:
    """Put robot and goal somewhere explicit, after a normal reset."""
    sim.reset(0, 'train')
    sim.world.set_goal(*goal)
    sim.world.set_robot_pose(x, y, yaw)
    sim.world.set_layout(type(sim.banks['train'][0])('train', -1, ()))  # no obstacles
    import mujoco
    mujoco.mj_forward(sim.world.model, sim.world.data)


def test_render_shape_dtype_and_content(sim):
    sim.reset(101, 'train')
    image = sim.render()
    assert image.shape == (CFG.camera_height, CFG.camera_width, 3)
    assert image.dtype == np.uint8
    assert image.std() > 1.0  # not a blank buffer


@pytest.mark.parametrize('mount', [
    {},
    {'camera_mount_forward': 0.038, 'camera_mount_height': 0.0455, 'camera_pitch_deg': 0.0},
    {'camera_mount_forward': -0.02, 'camera_mount_height': 0.2, 'camera_pitch_deg': -10.0},
])
def test_the_camera_sits_and_looks_where_configured(mount):
    config = SimConfig(**mount)
    sim = NavSim(config)
    try:
        place(sim, 0.2, -0.1, math.pi / 2, goal=(0.5, 0.0))
        cam = sim.world.camera_id
        expected = (0.2, -0.1 + config.camera_mount_forward, config.camera_mount_height)
        np.testing.assert_allclose(sim.world.data.cam_xpos[cam], expected, atol=1e-9)
        looking = -sim.world.data.cam_xmat[cam].reshape(3, 3)[:, 2]  # cameras look along -z
        pitch = math.radians(config.camera_pitch_deg)
        np.testing.assert_allclose(looking, (0.0, math.cos(pitch), -math.sin(pitch)), atol=1e-9)
        # no roll: the image's right is the robot's right (-y of the body = +x of the world here)
        np.testing.assert_allclose(sim.world.data.cam_xmat[cam].reshape(3, 3)[:, 0],
                                   (1.0, 0.0, 0.0), atol=1e-9)
    finally:
        sim.close()


@pytest.mark.parametrize('mount', [
    {},
    {'camera_mount_forward': 0.038, 'camera_mount_height': 0.0455, 'camera_pitch_deg': 0.0,
     'camera_hfov_deg': 48.0},
])
def test_the_coarse_depth_is_the_cameras_rendered_depth_at_its_cells(mount):
    import mujoco

    from nav_sim.core.depth import DEPTH_RANGE, DEPTH_SHAPE, depth_text, parse_depth
    config = SimConfig(world='clutter.xml', **mount)
    sim = NavSim(config)
    renderer = mujoco.Renderer(sim.world.model, config.camera_height, config.camera_width)
    renderer.enable_depth_rendering()
    rows, cols = DEPTH_SHAPE
    # each cell's centre lies between four pixels: compare where they agree (not an edge)
    y = np.floor((np.arange(rows) + 0.5) / rows * config.camera_height - 0.5).astype(int)
    x = np.floor((np.arange(cols) + 0.5) / cols * config.camera_width - 0.5).astype(int)
    compared = 0
    try:
        for seed in range(6):
            sim.reset(seed, 'train')
            renderer.update_scene(sim.world.data, camera=sim.world.camera_id)
            image = np.minimum(renderer.render(), DEPTH_RANGE)
            around = np.stack([image[np.ix_(y + dy, x + dx)] for dy in (0, 1) for dx in (0, 1)])
            depth = sim.depth()
            assert depth.shape == DEPTH_SHAPE and depth.dtype == np.float32
            assert (depth > 0).all() and (depth <= DEPTH_RANGE).all()
            smooth = around.max(axis=0) - around.min(axis=0) < 0.1 * around.min(axis=0)
            np.testing.assert_allclose(depth[smooth], around.mean(axis=0)[smooth], rtol=0.02)
            compared += int(smooth.sum())
            # the event carries it as text, to the millimetre
            np.testing.assert_allclose(parse_depth(depth_text(depth)), depth, atol=5e-4)
    finally:
        renderer.close()
        sim.close()
    assert compared > 0.8 * 6 * rows * cols  # the comparison saw most cells
    with pytest.raises(ValueError, match='64 cells, got 3'):
        parse_depth('1 2 3')


def test_the_coarse_depth_sees_a_wall_ahead_at_its_distance(sim):
    from nav_sim.core.depth import DEPTH_RANGE
    place(sim, 0.5, 0.0, 0.0, goal=(-0.5, 0.5))  # facing +x; the wall's face at x = 1.0
    before = sim.depth()
    # the top row's centre ray is above the horizontal: it meets the wall, whose z-depth on
    # the camera's tilted axis is the distance times cos(pitch) over cos of the ray's offset
    assert before[0].max() < DEPTH_RANGE
    sim.world.set_robot_pose(0.8, 0.0, 0.0)
    import mujoco
    mujoco.mj_forward(sim.world.model, sim.world.data)
    after = sim.depth()
    assert (after[0] < before[0] - 0.2).all()  # 30 cm closer: every top cell nearer
    np.testing.assert_allclose(after[2:], before[2:], atol=0.02)  # the floor just ahead: the same


def test_same_seed_gives_bit_identical_first_image():
    a, b = NavSim(), NavSim()
    try:
        a.reset(205, 'heldout')
        b.reset(0, 'train')
        b.reset(205, 'heldout')
        assert a.render().tobytes() == b.render().tobytes()
        a.reset(206, 'heldout')
        assert a.render().tobytes() != b.render().tobytes()
    finally:
        a.close()
        b.close()


def test_camera_looks_forward_and_sees_the_green_goal(sim):
    place(sim, 0.0, 0.0, 0.0, goal=(0.5, 0.0))
    ahead = sim.render().astype(int)
    green = (ahead[..., 1] > 150) & (ahead[..., 0] < 100) & (ahead[..., 2] < 100)
    assert green.sum() > 20
    cols = np.nonzero(green)[1]
    assert abs(cols.mean() - CFG.camera_width / 2) < 5  # centred
    place(sim, 0.0, 0.0, math.pi / 2, goal=(0.5, 0.0))  # goal is to the robot's right
    right = sim.render().astype(int)
    green = (right[..., 1] > 150) & (right[..., 0] < 100) & (right[..., 2] < 100)
    assert green.sum() == 0  # 90 degrees off-axis is outside the (90 degree) field of view


def test_each_action_moves_as_named(sim):
    place(sim, 0.0, 0.0, 0.3, goal=(0.8, 0.8))
    r = sim.step(FORWARD)
    x, y, yaw = r.pose
    travelled = math.hypot(x, y)
    assert travelled == pytest.approx(0.12 * CFG.ctrl_dt, rel=1e-6)
    assert math.atan2(y, x) == pytest.approx(0.3, abs=1e-6) and yaw == pytest.approx(0.3)
    r = sim.step(LEFT)  # counter-clockwise, in place
    assert r.pose[2] - yaw == pytest.approx(1.5 * CFG.ctrl_dt, rel=1e-6)
    assert r.pose[:2] == pytest.approx((x, y), abs=1e-9)
    r = sim.step(RIGHT)
    assert r.pose[2] == pytest.approx(yaw, abs=1e-9)


def test_goal_ends_the_period_early_and_stops_the_motors(sim):
    place(sim, 0.0, 0.0, 0.0, goal=(CFG.goal_radius + 0.01, 0.0))
    r = sim.step(FORWARD)
    assert r.event == EVENT_GOAL and r.done
    assert r.physics_steps < CFG.action_repeat
    assert r.distance <= CFG.goal_radius
    assert (sim.wheels.left, sim.wheels.right) == (0.0, 0.0)
    pose = r.pose
    r = sim.step(FORWARD)  # the episode is over: nothing moves until reset
    assert r.pose == pose and r.physics_steps == 0 and r.event == EVENT_GOAL


def test_collision_ends_the_period_early_and_stops_the_motors(sim):
    gap = 0.005  # 5 mm from the east wall
    place(sim, 1.0 - sim.world.geometry.robot_radius - gap, 0.0, 0.0, goal=(-0.5, 0.0))
    r = sim.step(FORWARD)
    assert r.event == EVENT_COLLISION and r.done
    assert 1 <= r.physics_steps < CFG.action_repeat
    assert (sim.wheels.left, sim.wheels.right) == (0.0, 0.0)


def test_obstacles_collide(sim):
    scenario = sim.reset(101, 'train')
    p = scenario.layout.placements[0]
    shape = sim.world.geometry.shapes[p.slot]
    d = shape.bounding_radius + sim.world.geometry.robot_radius + 0.01
    sim.world.set_robot_pose(p.x - d, p.y, 0.0)
    events = [sim.step(FORWARD).event for _ in range(10)]
    assert EVENT_COLLISION in events


def test_free_driving_reports_no_event(sim):
    place(sim, -0.5, 0.0, 0.0, goal=(0.8, 0.8))
    assert sim.step(FORWARD).event == EVENT_NONE


def test_step_before_reset_is_an_error():
    fresh = NavSim()
    try:
        with pytest.raises(EpisodeNotStartedError, match='reset'):
            fresh.step(FORWARD)
    finally:
        fresh.close()


def test_kinematics_round_trip_and_saturation():
    cmd = twist_to_wheels(0.05, 0.4, CFG)
    assert not cmd.saturated
    assert wheels_to_twist(cmd.left, cmd.right, CFG) == pytest.approx((0.05, 0.4))
    huge = twist_to_wheels(100.0, 50.0, CFG)
    assert huge.saturated
    assert max(abs(huge.left), abs(huge.right)) == pytest.approx(CFG.max_wheel_speed)
    v, w = wheels_to_twist(huge.left, huge.right, CFG)
    assert w / v == pytest.approx(0.5)  # curvature kept
    with pytest.raises(ValueError, match='non-finite'):
        twist_to_wheels(float('nan'), 0.0, CFG)


def test_sim_time_is_monotonic_across_resets(sim):
    sim.reset(1, 'train')
    t0 = sim.sim_time_ns
    sim.step(WheelCommand(0.0, 0.0))
    t1 = sim.sim_time_ns
    sim.reset(2, 'train')
    assert t0 < t1 < sim.sim_time_ns
    assert t1 - t0 == CFG.action_repeat * round(CFG.sim_dt * 1e9)


def green_share(image: np.ndarray) -> float:
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return float(((g > 120) & (g - r > 60) & (g - b > 60)).mean())


# The e-puck's own mount (front edge, level): the camera ends up ~1 cm from the goal marker at
# the success radius and ~1 cm from a wall, which is where a wrong near plane shows.
EPUCK_CAMERA = SimConfig(camera_mount_forward=0.038, camera_mount_height=0.0455,
                         camera_pitch_deg=0.0)


@pytest.fixture
def epuck_sim():
    core = NavSim(EPUCK_CAMERA)
    yield core
    core.close()


def test_the_goal_stays_visible_up_to_the_success_distance(epuck_sim):
    # At the success radius the camera is ~1 cm from the goal marker: it must fill the view
    # (MuJoCo's default near plane, relative to the model extent, used to clip it away).
    distance = CFG.goal_radius + 0.005  # just outside success
    place(epuck_sim, 0.0, 0.0, 0.0, (distance, 0.0))
    assert epuck_sim.distance > CFG.goal_radius
    assert green_share(epuck_sim.render()) > 0.5


def test_the_default_camera_keeps_the_goal_in_view_while_approaching(sim):
    shares = []
    for distance in (0.5, 0.3, 0.15, CFG.goal_radius + 0.005):
        place(sim, 0.0, 0.0, 0.0, (distance, 0.0))
        shares.append(green_share(sim.render()))
    assert shares == sorted(shares) and shares[0] > 0.02 and shares[-1] > 0.3, shares


def test_a_wall_just_ahead_is_seen(epuck_sim):
    """A wall 2 cm in front of the camera fills the image (no see-through near clipping)."""
    wall_x = 1.0  # inner face of the east wall
    camera_ahead = EPUCK_CAMERA.camera_mount_forward
    place(epuck_sim, wall_x - camera_ahead - 0.02, 0.0, 0.0, (-0.5, 0.0))
    image = epuck_sim.render().astype(int)
    wall = np.array([0.78, 0.76, 0.70]) * 255
    centre = image[20:76, 30:98].reshape(-1, 3)
    assert float(np.mean(np.abs(centre - wall).max(axis=1) < 60)) > 0.9


# --- any Twist: finite, bounded wheel speeds and a finite state (issue 10, defect 2) ---------
FLOAT64 = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
EXTREMES = [(1e308, 0.0), (0.0, 1.4e308), (3.7e306, 0.0), (-1.7e308, 1.4e308),
            (1.7976931348623157e308, -1.7976931348623157e308), (-1.7976931348623157e308, 1.0),
            (5e-324, -5e-324), (2.2250738585072014e-308, 1e308), (1e-320, 0.0),
            (math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan), (1e308, math.inf)]


def exact_wheels(linear: float, angular: float, config: SimConfig) -> tuple[Fraction, Fraction]:
    """Compute the saturated wheel speeds of a command in exact rational arithmetic."""
    half_axle, radius = Fraction(config.axle_length) / 2, Fraction(config.wheel_radius)
    left = (Fraction(linear) - Fraction(angular) * half_axle) / radius
    right = (Fraction(linear) + Fraction(angular) * half_axle) / radius
    peak, limit = max(abs(left), abs(right)), Fraction(config.max_wheel_speed)
    scale = limit / peak if peak > limit else Fraction(1)
    return left * scale, right * scale


def with_examples(test):  # noqa: ANN001, ANN201 - decorator
    for linear, angular in EXTREMES:
        test = example(linear, angular)(test)
    return test


@settings(max_examples=400, deadline=None, database=None)
@with_examples
@given(linear=FLOAT64, angular=FLOAT64)
def test_any_twist_gives_finite_wheel_speeds_within_the_limit(linear, angular):
    if not (math.isfinite(linear) and math.isfinite(angular)):
        with pytest.raises(ValueError, match='non-finite'):  # the node stops the motors
            twist_to_wheels(linear, angular, CFG)
        return
    command = twist_to_wheels(linear, angular, CFG)
    limit = CFG.max_wheel_speed
    for speed in (command.left, command.right):
        assert math.isfinite(speed) and abs(speed) <= limit
    # the same wheel speeds as exact arithmetic gives, so the curvature is kept to rounding
    left, right = exact_wheels(linear, angular, CFG)
    tolerance = 1e-12 * float(max(abs(left), abs(right))) + 1e-300
    assert abs(command.left - float(left)) <= tolerance
    assert abs(command.right - float(right)) <= tolerance
    peak = max(abs(left), abs(right)) / Fraction(limit)
    if abs(peak - 1) > Fraction(1, 10**9):
        assert command.saturated == (peak > 1)


@settings(max_examples=60, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@with_examples
@given(linear=FLOAT64, angular=FLOAT64)
def test_no_twist_makes_the_sim_state_non_finite(sim, linear, angular):
    try:
        command = twist_to_wheels(linear, angular, CFG)
    except ValueError:
        command = WheelCommand(0.0, 0.0)  # what sim_node does with a non-finite command
    if sim.scenario is None or sim.done:
        sim.reset(101, 'train')
    result = sim.step(command)
    assert all(math.isfinite(v) for v in (*result.pose, result.distance, sim.path_length))
    assert all(math.isfinite(v) for v in sim.twist)
