"""What the live view and the evaluation bags show, as ROS 2 messages (no rclpy, no Foxglove).

One definition of the visualisation topics, their ROS 2 types and their CDR bytes, shared by the
sim node's live view, the trainer's and evaluator's live view (:mod:`nav_sim.viz.server`) and the
evaluation bags (:mod:`nav_eval.recording.recorder`), so that one Foxglove layout
(``config/foxglove/visnav.json``) serves a live connection and a recorded bag.

Messages are ``rosbags`` dataclasses serialized to CDR by its typestore (ROS 2 Jazzy types plus
the two ``visnav_msgs`` types below, which have no ROS package: Foxglove and ``rosbags`` read them
from the schema stored with each channel).

The 3D scene is ``visualization_msgs/MarkerArray`` in the ``odom`` frame (no ``/tf``: the
``tf2_msgs`` package is not among the ROS 2 wheels, and every marker already carries its pose):

* ``/visnav/scene``: the episode's static world: floor, walls, obstacles, the goal beacon and the
  success radius around it; sent at each reset (after a ``DELETEALL``) and when a viewer
  subscribes.
* ``/visnav/robot``: every control period: the robot body, an arrow along its heading, the
  camera's view frustum and the path of the current episode.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from nav_sim import interface
from nav_sim.core.geometry import ArenaGeometry, Box, ObstacleShape

CAMERA_TOPIC = f'/{interface.IMAGE_TOPIC}'  # the sim's topics in the default namespace
EVENT_TOPIC = f'/{interface.EVENT_TOPIC}'
DIAGNOSTICS_TOPIC = '/diagnostics'
SCENE_TOPIC = '/visnav/scene'
ROBOT_TOPIC = '/visnav/robot'
OBSERVATION_TOPIC = '/visnav/observation'
STEP_TOPIC = '/visnav/step'
TRAINING_TOPIC = '/visnav/training'
DECISION_TOPIC = f'/{interface.DECISION_TOPIC}'  # the policy node's decisions

MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
STEP_TYPE = 'visnav_msgs/msg/EnvStep'
TRAINING_TYPE = 'visnav_msgs/msg/TrainingStats'

#: topic -> ROS 2 type, for every topic a live view may advertise
TOPIC_TYPES = {
    CAMERA_TOPIC: interface.IMAGE_TYPE,
    EVENT_TOPIC: interface.EVENT_TYPE,
    DIAGNOSTICS_TOPIC: interface.EVENT_TYPE,
    SCENE_TOPIC: MARKERS_TYPE,
    ROBOT_TOPIC: MARKERS_TYPE,
    OBSERVATION_TOPIC: interface.IMAGE_TYPE,
    STEP_TOPIC: STEP_TYPE,
    TRAINING_TOPIC: TRAINING_TYPE,
    DECISION_TOPIC: interface.DECISION_TYPE,
}
#: what a standalone sim node's live view serves
SIM_TOPICS = (CAMERA_TOPIC, EVENT_TOPIC, DIAGNOSTICS_TOPIC, SCENE_TOPIC, ROBOT_TOPIC)
#: what a trainer's or evaluator's live view serves (it sees the sim through its env)
ENV_TOPICS = (CAMERA_TOPIC, DIAGNOSTICS_TOPIC, SCENE_TOPIC, ROBOT_TOPIC, OBSERVATION_TOPIC,
              STEP_TOPIC, TRAINING_TOPIC)
#: what only a graph with the policy node has (the closed-loop evaluation, the demo, a robot)
POLICY_TOPICS = (DECISION_TOPIC,)
#: what the closed-loop evaluation's (and the demo's) live view serves
CLOSED_LOOP_TOPICS = (*ENV_TOPICS, *POLICY_TOPICS)

ENV_STEP_MSG = """\
builtin_interfaces/Time stamp
uint32 episode
uint32 step
int32 action
string action_name
float64 reward
float64 reward_progress
float64 reward_step
float64 reward_goal
float64 reward_collision
float64 episode_return
float64 distance
string event
float64[] q_values
"""
TRAINING_STATS_MSG = """\
builtin_interfaces/Time stamp
uint64 num_timesteps
uint32 episodes
float64 exploration_rate
float64 rolling_return
float64 rolling_success_rate
float64 rolling_length
"""


def register_types(typestore: Any) -> Any:
    """Add the ``visnav_msgs`` types to a rosbags typestore (idempotent); return it."""
    if STEP_TYPE not in typestore.types:
        types = get_types_from_msg(ENV_STEP_MSG, STEP_TYPE)
        types.update(get_types_from_msg(TRAINING_STATS_MSG, TRAINING_TYPE))
        typestore.register(types)
    return typestore


TYPESTORE = register_types(get_typestore(Stores.ROS2_JAZZY))
_T = TYPESTORE.types


def schema_text(msgtype: str) -> str:
    """Return the ``ros2msg`` schema of a type (with its dependencies, as MCAP stores it)."""
    return TYPESTORE.generate_msgdef(msgtype, ros_version=2)[0]


def to_cdr(msg: Any, msgtype: str) -> bytes:
    """CDR bytes of a rosbags message."""
    return bytes(TYPESTORE.serialize_cdr(msg, msgtype))


def from_cdr(data: bytes | memoryview, msgtype: str) -> Any:
    """Deserialize CDR bytes to a rosbags message."""
    return TYPESTORE.deserialize_cdr(data, msgtype)


# --- plain messages ---------------------------------------------------------------------------
def _time(stamp_ns: int) -> Any:
    return _T['builtin_interfaces/msg/Time'](sec=stamp_ns // 1_000_000_000,
                                             nanosec=stamp_ns % 1_000_000_000)


def _header(stamp_ns: int, frame_id: str) -> Any:
    return _T['std_msgs/msg/Header'](stamp=_time(stamp_ns), frame_id=frame_id)


def image(rgb: np.ndarray, stamp_ns: int, frame_id: str) -> Any:
    """Build an ``rgb8`` sensor_msgs/Image of an (H, W, 3) uint8 array."""
    height, width, _ = rgb.shape
    return _T[interface.IMAGE_TYPE](header=_header(stamp_ns, frame_id), height=height, width=width,
                          encoding='rgb8', is_bigendian=0, step=width * 3,
                          data=np.ascontiguousarray(rgb, dtype=np.uint8).reshape(-1))


def observation_image(obs: np.ndarray, stamp_ns: int) -> Any:
    """Build an ``rgb8`` Image of the policy's (3, 84, 84) channel-first observation."""
    return image(np.ascontiguousarray(obs.transpose(1, 2, 0)), stamp_ns, 'observation')


def diagnostics(statuses: list[tuple[str, str, dict[str, Any]]], stamp_ns: int) -> Any:
    """Build a DiagnosticArray of ``(name, message, key/values)`` statuses, level OK."""
    kv, status = _T['diagnostic_msgs/msg/KeyValue'], _T['diagnostic_msgs/msg/DiagnosticStatus']
    return _T[interface.EVENT_TYPE](header=_header(stamp_ns, ''), status=[
        status(level=bytes([0]), name=name, message=message, hardware_id='visnav',
               values=[kv(key=k, value=str(v)) for k, v in values.items()])
        for name, message, values in statuses])


def env_step(stamp_ns: int, episode: int, step: int, action: int, action_name: str,
             reward: float, terms: dict[str, float], episode_return: float, distance: float,
             event: str, q_values: Any = None) -> Any:
    """Build a ``visnav_msgs/EnvStep``: what one env step did and earned."""
    q = np.asarray([] if q_values is None else q_values, dtype=np.float64).reshape(-1)
    return _T[STEP_TYPE](
        stamp=_time(stamp_ns), episode=int(episode), step=int(step), action=int(action),
        action_name=action_name, reward=float(reward),
        reward_progress=float(terms.get('progress', 0.0)),
        reward_step=float(terms.get('step', 0.0)), reward_goal=float(terms.get('goal', 0.0)),
        reward_collision=float(terms.get('collision', 0.0)),
        episode_return=float(episode_return), distance=float(distance), event=event,
        q_values=q)


def training_stats(stamp_ns: int, num_timesteps: int, episodes: int, exploration_rate: float,
                   rolling_return: float, rolling_success_rate: float,
                   rolling_length: float) -> Any:
    """Build a ``visnav_msgs/TrainingStats``: the learner's progress."""
    return _T[TRAINING_TYPE](
        stamp=_time(stamp_ns), num_timesteps=int(num_timesteps), episodes=int(episodes),
        exploration_rate=float(exploration_rate), rolling_return=float(rolling_return),
        rolling_success_rate=float(rolling_success_rate),
        rolling_length=float(rolling_length))


# --- the 3D scene -----------------------------------------------------------------------------
@dataclass(frozen=True)
class ArenaScene:
    """The dimensions the 3D view draws, read once from the loaded world, and its frame."""

    half_size: float
    walls: tuple[Box, ...]
    slots: tuple[ObstacleShape, ...]
    goal_marker_radius: float
    goal_marker_height: float
    goal_radius: float
    robot_radius: float
    robot_height: float
    camera_forward: float
    camera_height: float
    camera_pitch: float       # radians below the horizontal
    camera_half_hfov: float   # radians
    camera_half_vfov: float   # radians
    frame: str = interface.ODOM_FRAME  # the frame of every marker: the sim's odom_frame

    @classmethod
    def from_geometry(cls, geometry: ArenaGeometry, cfg: Any,
                      frame: str = interface.ODOM_FRAME) -> ArenaScene:
        """Build the scene of an arena and its SimConfig ``cfg``, drawn in ``frame``."""
        return cls(geometry.half_size, tuple(Box(*wall) for wall in geometry.walls),
                   geometry.shapes, cfg.goal_marker_radius, cfg.goal_marker_height,
                   cfg.goal_radius, geometry.robot_radius, geometry.robot_height,
                   cfg.camera_mount_forward, cfg.camera_mount_height,
                   math.radians(cfg.camera_pitch_deg), math.radians(cfg.camera_hfov_deg) / 2.0,
                   math.radians(cfg.camera_fovy_deg) / 2.0, frame)

    @classmethod
    def from_world(cls, world: Any, frame: str = interface.ODOM_FRAME) -> ArenaScene:
        """Build the scene of a loaded :class:`nav_sim.core.world.World`, drawn in ``frame``."""
        return cls.from_geometry(world.geometry, world.config, frame)


def arena_for(sim_params: dict[str, Any] | None = None) -> ArenaScene:
    """Return the :class:`ArenaScene` of a sim parameter mapping (loads the MJCF only).

    Drawn in the mapping's ``odom_frame`` (a sim node parameter), else the default frame.
    """
    from nav_sim.core.world import load_arena  # MuJoCo: only where a scene is drawn
    frame = str((sim_params or {}).get('odom_frame', interface.ODOM_FRAME))
    return ArenaScene.from_geometry(*load_arena(sim_params), frame)


FRUSTUM_DEPTH = 0.35   # metres drawn along the camera's view
FLOOR = (0.85, 0.85, 0.82, 1.0)
WALL = (0.55, 0.55, 0.6, 1.0)
OBSTACLE = (0.9, 0.3, 0.15, 1.0)
GOAL = (0.1, 0.8, 0.2, 1.0)
GOAL_ZONE = (0.1, 0.8, 0.2, 0.25)
ROBOT = (0.95, 0.95, 0.95, 1.0)
HEADING = (0.1, 0.3, 0.9, 1.0)
FRUSTUM = (0.2, 0.2, 0.2, 1.0)
PATH = (0.1, 0.3, 0.9, 0.8)
_SHAPES = {'cube': 1, 'sphere': 2, 'cylinder': 3, 'line_strip': 4, 'line_list': 5, 'arrow': 0}


# the unused parts of every marker, built once (serializing only reads them)
_FOREVER = _T['builtin_interfaces/msg/Duration'](sec=0, nanosec=0)
_NO_TEXTURE = _T['sensor_msgs/msg/CompressedImage'](header=_header(0, ''), format='',
                                                    data=np.zeros(0, np.uint8))
_NO_MESH = _T['visualization_msgs/msg/MeshFile'](filename='', data=np.zeros(0, np.uint8))


def _marker(stamp_ns: int, frame: str, ns: str, marker_id: int, shape: str, *,
            position: tuple[float, float, float] = (0.0, 0.0, 0.0), yaw: float = 0.0,
            scale: tuple[float, float, float] = (1.0, 1.0, 1.0),
            color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0),
            points: list[tuple[float, float, float]] | None = None, action: int = 0) -> Any:
    point, vector = _T['geometry_msgs/msg/Point'], _T['geometry_msgs/msg/Vector3']
    quaternion = _T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=math.sin(yaw / 2.0),
                                                    w=math.cos(yaw / 2.0))
    return _T['visualization_msgs/msg/Marker'](
        header=_header(stamp_ns, frame), ns=ns, id=marker_id, type=_SHAPES[shape],
        action=action,
        pose=_T['geometry_msgs/msg/Pose'](position=point(*position), orientation=quaternion),
        scale=vector(*scale), color=_T['std_msgs/msg/ColorRGBA'](*color),
        lifetime=_FOREVER, frame_locked=False, points=[point(*p) for p in points or ()],
        colors=[], texture_resource='', texture=_NO_TEXTURE, uv_coordinates=[], text='',
        mesh_resource='', mesh_file=_NO_MESH, mesh_use_embedded_materials=False)


def look_colours(scenario: dict[str, Any]) -> dict[str, tuple[float, float, float, float]]:
    """Return the floor, wall and obstacle colours of an episode: its drawn look's, else plain."""
    look = scenario.get('look') or {}
    plain = {'floor': FLOOR, 'walls': WALL, 'obstacles': OBSTACLE}
    return {k: ((*(float(v) for v in look[k][:3]), 1.0) if k in look else colour)
            for k, colour in plain.items()}


def scene_markers(arena: ArenaScene, scenario: dict[str, Any], stamp_ns: int) -> Any:
    """Build the static world of an episode: floor, walls, obstacles, goal.

    ``scenario`` is the episode description, ``Scenario.to_dict()``, which is also what the
    sim's ``reset`` service returns; a drawn look in it (``look``) colours the floor, walls and
    obstacles.
    """
    colours = look_colours(scenario)
    marker = functools.partial(_marker, stamp_ns, arena.frame)
    markers = [marker('', 0, 'cube', action=3)]  # DELETEALL: the previous episode's
    size = 2.0 * arena.half_size
    markers.append(marker('floor', 0, 'cube', position=(0.0, 0.0, -0.005),
                           scale=(size, size, 0.01), color=colours['floor']))
    for i, w in enumerate(arena.walls):
        markers.append(marker('walls', i, 'cube', position=(w.x, w.y, w.z),
                               scale=(2 * w.half_x, 2 * w.half_y, 2 * w.half_z),
                               color=colours['walls']))
    for i, place in enumerate(scenario.get('obstacles', ())):
        shape = arena.slots[int(place['slot'])]
        markers.append(marker(
            'obstacles', i, shape.kind if shape.kind == 'cylinder' else 'cube',
            position=(float(place['x']), float(place['y']), shape.half_z),
            yaw=float(place['yaw']), scale=(2 * shape.half_x, 2 * shape.half_y, 2 * shape.half_z),
            color=colours['obstacles']))
    gx, gy = (float(v) for v in scenario['goal'])
    markers.append(marker('goal', 0, 'cylinder',
                           position=(gx, gy, arena.goal_marker_height / 2.0),
                           scale=(2 * arena.goal_marker_radius, 2 * arena.goal_marker_radius,
                                  arena.goal_marker_height), color=GOAL))
    markers.append(marker('goal', 1, 'cylinder', position=(gx, gy, 0.001),
                           scale=(2 * arena.goal_radius, 2 * arena.goal_radius, 0.002),
                           color=GOAL_ZONE))
    return _T[MARKERS_TYPE](markers=markers)


def _frustum_lines(arena: ArenaScene, pose: tuple[float, float, float]
                   ) -> list[tuple[float, float, float]]:
    """Line-list points of the camera's view pyramid, ``FRUSTUM_DEPTH`` deep, in odom."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    apex_body = (arena.camera_forward, 0.0, arena.camera_height)
    corners = []
    for sy, sz in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        # a ray in the camera frame (forward, left, up), then pitched down about the body y axis
        fwd, left, up = 1.0, sy * math.tan(arena.camera_half_hfov), sz * math.tan(
            arena.camera_half_vfov)
        cp, sp = math.cos(arena.camera_pitch), math.sin(arena.camera_pitch)
        bx, bz = fwd * cp + up * sp, -fwd * sp + up * cp
        norm = math.sqrt(bx * bx + left * left + bz * bz)
        d = FRUSTUM_DEPTH / norm
        corners.append((apex_body[0] + bx * d, left * d, max(apex_body[2] + bz * d, 0.0)))

    def world(p: tuple[float, float, float]) -> tuple[float, float, float]:
        return (x + c * p[0] - s * p[1], y + s * p[0] + c * p[1], p[2])

    apex = world(apex_body)
    ring = [world(p) for p in corners]
    lines = []
    for i, corner in enumerate(ring):
        lines += [apex, corner, corner, ring[(i + 1) % len(ring)]]
    return lines


def robot_markers(arena: ArenaScene, pose: tuple[float, float, float],
                  path: list[tuple[float, float]], stamp_ns: int) -> Any:
    """Build the robot at ``pose``: body, heading arrow, camera frustum, the episode's path."""
    x, y, yaw = pose
    r, h = arena.robot_radius, arena.robot_height
    marker = functools.partial(_marker, stamp_ns, arena.frame)
    markers = [
        marker('robot', 0, 'cylinder', position=(x, y, h / 2.0),
                scale=(2 * r, 2 * r, h), color=ROBOT),
        marker('robot', 1, 'arrow', position=(x, y, h + 0.005), yaw=yaw,
                scale=(3 * r, 0.012, 0.012), color=HEADING),
        marker('robot', 2, 'line_list', scale=(0.004, 0.0, 0.0), color=FRUSTUM,
                points=_frustum_lines(arena, pose)),
    ]
    if len(path) >= 2:
        markers.append(marker('path', 0, 'line_strip', scale=(0.008, 0.0, 0.0),
                               color=PATH, points=[(px, py, 0.003) for px, py in path]))
    else:  # a new episode: remove the previous path
        markers.append(marker('path', 0, 'line_strip', action=2))
    return _T[MARKERS_TYPE](markers=markers)
