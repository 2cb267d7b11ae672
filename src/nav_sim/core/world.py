"""The MuJoCo world: load the MJCF, look up named ids, place things and render the camera.

No task logic here (see ``scenarios.py`` and ``sim.py``).  Rendering is offscreen;
``MUJOCO_GL`` defaults to ``egl`` (set in ``nav_sim/__init__``; Debian packages ``libegl1`` and
``libgl1-mesa-dri``).
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from nav_sim.core.config import SimConfig
from nav_sim.core.contract import (
    BASE_JOINTS,
    CAMERA,
    FLOOR,
    GOAL,
    OBSTACLE_PREFIX,
    ROBOT,
    ROBOT_GEOM,
    WALL_PREFIX,
    read_arena,
    shown_material,
)
from nav_sim.core.contract import load_world as load_checked
from nav_sim.core.depth import DEPTH_RANGE, DEPTH_SHAPE, cell_rays
from nav_sim.core.geometry import ArenaGeometry, Layout
from nav_sim.core.looks import Look

PARKED = np.array([10.0, 10.0, -1.0])  # where unused obstacle slots wait, out of sight


class World:
    """An MJCF model with its data, named ids and a fast offscreen camera renderer."""

    def __init__(self, config: SimConfig) -> None:
        """Load and check the configured world, apply the config and look up the ids.

        A world that breaks the contract raises WorldError (``nav_sim.core.contract``).
        """
        self.config = config
        self.path, self.model = load_checked(config)
        self.data = mujoco.MjData(self.model)
        self._configure_model()
        self._ids()
        self.geometry = read_arena(self.model)
        self._plain_look = self._look_state()
        self._renderer: mujoco.Renderer | None = None
        rays = cell_rays(config.camera_hfov_deg, config.camera_width, config.camera_height)
        # a rotation keeps lengths: the unit rays and their lengths are computed once
        self._ray_lengths = np.linalg.norm(rays, axis=1)
        self._unit_rays = rays / self._ray_lengths[:, None]
        self._ray_geoms = np.zeros(len(rays), np.int32)
        self._ray_distances = np.zeros(len(rays))

    def _configure_model(self) -> None:
        m, cfg = self.model, self.config
        m.opt.timestep = cfg.sim_dt
        m.vis.quality.offsamples = 0
        m.vis.global_.offwidth = max(cfg.camera_width, 1)
        m.vis.global_.offheight = max(cfg.camera_height, 1)
        cam = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA)
        m.cam_fovy[cam] = cfg.camera_fovy_deg
        self._mount_camera(cam)
        # MuJoCo's clipping planes are relative to the model extent, which the parked obstacle
        # slots inflate to metres: the default near plane would hide anything within ~7 cm of
        # the camera (the goal at the moment of success, a wall just before a collision).
        m.vis.map.znear = cfg.camera_near_clip / m.stat.extent
        goal = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, GOAL)
        m.geom_size[goal, :2] = (cfg.goal_marker_radius, cfg.goal_marker_height / 2.0)
        m.geom_rbound[goal] = math.hypot(cfg.goal_marker_radius, cfg.goal_marker_height / 2.0)

    def _mount_camera(self, cam: int) -> None:
        """Place the camera on the robot: ahead of its centre, above the floor, tilted down."""
        m, cfg = self.model, self.config
        body_z = float(m.body_pos[m.cam_bodyid[cam]][2])
        m.cam_pos[cam] = (cfg.camera_mount_forward, 0.0, cfg.camera_mount_height - body_z)
        pitch = math.radians(cfg.camera_pitch_deg)
        # MuJoCo cameras look along their -z axis with +x right and +y up in the image
        right = np.array([0.0, -1.0, 0.0])
        up = np.array([math.sin(pitch), 0.0, math.cos(pitch)])
        rotation = np.column_stack([right, up, np.cross(right, up)])
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, rotation.flatten())
        m.cam_quat[cam] = quat

    def _ids(self) -> None:
        m = self.model
        name2id = mujoco.mj_name2id
        self.camera_id = name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA)
        self.robot_geom = name2id(m, mujoco.mjtObj.mjOBJ_GEOM, ROBOT_GEOM)
        self.robot_body = name2id(m, mujoco.mjtObj.mjOBJ_BODY, ROBOT)
        joints = [name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j[0]) for j in BASE_JOINTS]
        self.qpos_slice = _consecutive([int(m.jnt_qposadr[j]) for j in joints], 'qpos')
        self.qvel_slice = _consecutive([int(m.jnt_dofadr[j]) for j in joints], 'qvel')
        self.goal_mocap = m.body_mocapid[name2id(m, mujoco.mjtObj.mjOBJ_BODY, GOAL)]
        self.obstacle_geoms: list[int] = []
        self.obstacle_mocaps: list[int] = []
        index = 0
        while (body := name2id(m, mujoco.mjtObj.mjOBJ_BODY, f'{OBSTACLE_PREFIX}{index}')) >= 0:
            self.obstacle_mocaps.append(int(m.body_mocapid[body]))
            self.obstacle_geoms.append(name2id(m, mujoco.mjtObj.mjOBJ_GEOM,
                                               f'{OBSTACLE_PREFIX}{index}'))
            index += 1
        self.wall_geoms = [g for g in range(m.ngeom) if m.geom(g).name.startswith(WALL_PREFIX)]
        self.floor_geom = name2id(m, mujoco.mjtObj.mjOBJ_GEOM, FLOOR)

    # --- the look -------------------------------------------------------------------------
    def _look_state(self) -> dict[str, np.ndarray]:
        """Copy what a look changes: surface colours, the lights, the headlight's ambient."""
        m = self.model
        return {'mat_rgba': m.mat_rgba.copy(), 'geom_rgba': m.geom_rgba.copy(),
                'light_dir': m.light_dir.copy(), 'light_diffuse': m.light_diffuse.copy(),
                'ambient': m.vis.headlight.ambient.copy()}

    def apply_look(self, look: Look | None) -> None:
        """Paint a drawn look on the model (None: the world's own look).

        Floor, walls and obstacles take the look's colours (through their materials, which
        tint a texture; a geom without a material directly); every light shines from the
        look's direction with its intensity, and the headlight's ambient is the look's.  The
        goal is never touched.  Call ``mj_forward`` after it (a reset does).
        """
        m, plain = self.model, self._plain_look
        m.mat_rgba[:], m.geom_rgba[:] = plain['mat_rgba'], plain['geom_rgba']
        m.light_dir[:], m.light_diffuse[:] = plain['light_dir'], plain['light_diffuse']
        m.vis.headlight.ambient[:] = plain['ambient']
        if look is None:
            return
        surfaces = ((look.floor, [self.floor_geom]), (look.walls, self.wall_geoms),
                    (look.obstacles, self.obstacle_geoms))
        for colour, geoms in surfaces:
            for geom in geoms:
                material = shown_material(m, geom)
                if material >= 0:
                    m.mat_rgba[material, :3] = colour
                else:
                    m.geom_rgba[geom, :3] = colour
        m.light_dir[:] = look.light_dir
        m.light_diffuse[:] = look.light_diffuse
        m.vis.headlight.ambient[:] = look.ambient

    # --- placing things -------------------------------------------------------------------
    def set_layout(self, layout: Layout) -> None:
        """Move the layout's obstacle slots into the arena and park the others."""
        placed = {p.slot: p for p in layout.placements}
        for slot, mocap in enumerate(self.obstacle_mocaps):
            height = self.model.geom_size[self.obstacle_geoms[slot]][-1]
            if slot in placed:
                p = placed[slot]
                self.data.mocap_pos[mocap] = (p.x, p.y, height)
                self.data.mocap_quat[mocap] = (math.cos(p.yaw / 2), 0.0, 0.0,
                                               math.sin(p.yaw / 2))
            else:
                self.data.mocap_pos[mocap] = PARKED + (slot, 0.0, 0.0)
                self.data.mocap_quat[mocap] = (1.0, 0.0, 0.0, 0.0)

    def set_goal(self, x: float, y: float) -> None:
        """Move the goal marker to (x, y), resting on the floor."""
        self.data.mocap_pos[self.goal_mocap] = (x, y, self.config.goal_marker_height / 2.0)

    def set_robot_pose(self, x: float, y: float, yaw: float) -> None:
        """Put the robot base at (x, y, yaw) and zero its velocity."""
        self.data.qpos[self.qpos_slice] = (x, y, yaw)
        self.data.qvel[self.qvel_slice] = 0.0

    def robot_pose(self) -> tuple[float, float, float]:
        """Return the robot base pose (x, y, yaw), with yaw wrapped to [-pi, pi]."""
        x, y, yaw = (float(v) for v in self.data.qpos[self.qpos_slice])
        return x, y, math.remainder(yaw, 2.0 * math.pi)

    def goal_position(self) -> tuple[float, float]:
        """Return the goal marker's (x, y) position."""
        pos = self.data.mocap_pos[self.goal_mocap]
        return float(pos[0]), float(pos[1])

    def robot_in_collision(self) -> bool:
        """Return True if a MuJoCo contact touches the robot body.

        Only walls and obstacles collide with it.
        """
        d = self.data
        for i in range(d.ncon):
            contact = d.contact[i]
            if self.robot_geom in (contact.geom1, contact.geom2) and contact.dist <= 0.0:
                return True
        return False

    # --- rendering ------------------------------------------------------------------------
    def renderer(self) -> mujoco.Renderer:
        """Return the offscreen camera renderer, creating it on first use.

        Shadows, reflections and the skybox are switched off.
        """
        if self._renderer is None:
            r = mujoco.Renderer(self.model, self.config.camera_height, self.config.camera_width)
            for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION,
                         mujoco.mjtRndFlag.mjRND_SKYBOX):
                r.scene.flags[flag] = 0
            self._renderer = r
        return self._renderer

    def render_camera(self) -> np.ndarray:
        """Render the robot camera image, (height, width, 3) uint8 RGB."""
        r = self.renderer()
        r.update_scene(self.data, camera=self.camera_id)
        return r.render()

    def camera_depth(self) -> np.ndarray:
        """Return the camera's coarse depth, ``DEPTH_SHAPE`` float32 (``nav_sim.core.depth``).

        One ray per cell from the camera through the cell's centre (MuJoCo's ``mj_multiRay``
        over every geom, as the camera renders them), on the poses of the last forward pass.
        """
        m, d, cam = self.model, self.data, self.camera_id
        rays = self._unit_rays @ d.cam_xmat[cam].reshape(3, 3).T  # camera to world frame
        lengths = self._ray_lengths
        mujoco.mj_multiRay(m, d, d.cam_xpos[cam].copy(), rays.ravel(),
                           None, 1, -1, self._ray_geoms, self._ray_distances,
                           None, len(rays), DEPTH_RANGE * float(lengths.max()))
        depth = np.where(self._ray_geoms >= 0, self._ray_distances / lengths, DEPTH_RANGE)
        return np.minimum(depth, DEPTH_RANGE).astype(np.float32).reshape(DEPTH_SHAPE)

    def close(self) -> None:
        """Release the renderer, if one was created."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def load_arena(sim_params: dict[str, Any] | None = None) -> tuple[ArenaGeometry, SimConfig]:
    """Return the arena of a sim parameter mapping and its SimConfig (loads the MJCF only)."""
    config = SimConfig.from_params(dict(sim_params or {}))
    world = World(config)
    try:
        return world.geometry, config
    finally:
        world.close()


def _consecutive(addresses: list[int], what: str) -> slice:
    """Return the base joints' (x, y, yaw) addresses as one slice.

    A slice indexes a view, which is cheap in the hot loop; raise ValueError if the addresses
    are not consecutive.
    """
    first = addresses[0]
    if addresses != list(range(first, first + len(addresses))):
        raise ValueError(f'the robot base joints must be consecutive in {what}, got {addresses}')
    return slice(first, first + len(addresses))
