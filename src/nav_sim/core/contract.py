"""The world contract: what a world file must contain, checked whenever nav_sim loads one.

``REQUIRED`` is the one list of the named elements a world needs (docs/worlds.md shows it as a
table, and its minimal example world is tested against it); :func:`load_world` finds, parses,
compiles and checks a world and raises one :class:`nav_sim.errors.WorldError` whose message has
one line per violation, each naming the file and the element.  A world breaks the contract by
missing a required element, by giving one the wrong type or place (a camera not on the robot,
a floor that collides), by a colliding geom the scenarios would not know, by an arena too small
for any scenario or by a colour other than the goal's in the goal's hues.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from nav_sim.core.config import SimConfig
from nav_sim.core.geometry import ArenaGeometry, Box, ObstacleShape
from nav_sim.core.looks import green_excess
from nav_sim.core.scenarios import START_CLEARANCE, goal_clearance
from nav_sim.core.world_file import parse_xml
from nav_sim.errors import WorldError
from nav_sim.paths import find_world

ROBOT, ROBOT_GEOM, CAMERA = 'robot', 'robot_body', 'front_camera'
#: the robot base's planar joints, in qpos order: (name, type, axis)
BASE_JOINTS = (('base_x', 'slide', (1.0, 0.0, 0.0)), ('base_y', 'slide', (0.0, 1.0, 0.0)),
               ('base_yaw', 'hinge', (0.0, 0.0, 1.0)))
FLOOR, GOAL = 'floor', 'goal'
WALL_PREFIX, OBSTACLE_PREFIX = 'wall_', 'obstacle_'
#: the outer walls: (axis, side) of the inner face that bounds the square arena
OUTER_WALLS = {'wall_east': (0, 1), 'wall_west': (0, -1), 'wall_north': (1, 1),
               'wall_south': (1, -1)}
SIZE_WALL = 'wall_east'  # the outer wall whose inner face gives the arena's half size
GOAL_MIN_GREEN = 0.4    # the goal's green exceeds its red and blue by this much at least
OTHER_MAX_GREEN = 0.05  # ... and no other visible colour's by more than this
VISIBLE_GROUPS = 3      # geoms of groups 0-2 are drawn (MuJoCo's default)
_TOLERANCE = 1e-6       # m: how exactly the outer walls must enclose the square
_KINDS = {'body': mujoco.mjtObj.mjOBJ_BODY, 'joint': mujoco.mjtObj.mjOBJ_JOINT,
          'geom': mujoco.mjtObj.mjOBJ_GEOM, 'camera': mujoco.mjtObj.mjOBJ_CAMERA}


@dataclass(frozen=True)
class Element:
    """One named element a world must contain, and what it must be."""

    kind: str
    name: str
    rule: str


REQUIRED = (
    Element('body', ROBOT, 'the robot base: a body of the worldbody, not mocap'),
    *(Element('joint', name, f"a {kind} joint {'along' if kind == 'slide' else 'about'} "
              f"{'xyz'[axis.index(1.0)]} on body '{ROBOT}'")
      for name, kind, axis in BASE_JOINTS),
    Element('geom', ROBOT_GEOM, f"a cylinder on body '{ROBOT}' that collides with the walls "
            'and obstacles: the footprint'),
    Element('camera', CAMERA, f"the forward camera, on body '{ROBOT}'"),
    Element('geom', FLOOR, 'a plane that collides with nothing'),
    *(Element('geom', name, f"a box whose inner face bounds the square arena at "
              f"{'-' if side < 0 else '+'}{'xy'[axis]}") for name, (axis, side) in
      OUTER_WALLS.items()),
    Element('body', GOAL, 'the goal marker: a mocap body'),
    Element('geom', GOAL, f"a green cylinder on body '{GOAL}' that collides with nothing"),
    Element('body', f'{OBSTACLE_PREFIX}0', 'the first obstacle slot: a mocap body (slots '
            f'{OBSTACLE_PREFIX}0, {OBSTACLE_PREFIX}1, ...: at least num_obstacles)'),
    Element('geom', f'{OBSTACLE_PREFIX}0', f"a box or cylinder on body '{OBSTACLE_PREFIX}0' "
            'that collides with the robot'),
)


def load_model(path: Path) -> mujoco.MjModel:
    """Parse and compile a world file, or raise WorldError naming the file and the line."""
    parse_xml(path)  # malformed XML: the line and column, in one line
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        raise WorldError(f'{path}: MuJoCo cannot load it: {" ".join(str(exc).split())}'
                         ) from None


def load_world(config: SimConfig) -> tuple[Path, mujoco.MjModel]:
    """Find, load and check the world of ``config``; raise WorldError with every violation."""
    path = find_world(config.world)
    model = load_model(path)
    problems = check_model(model, path, config)
    if problems:
        raise WorldError('\n'.join(problems))
    return path, model


def shown_material(model: mujoco.MjModel, geom: int) -> int:
    """Return the material whose colour a geom shows, or -1 when it shows its own rgba.

    MuJoCo draws a geom's material colour unless the geom sets an rgba of its own (any other
    than the default grey).
    """
    material = int(model.geom_matid[geom])
    if material >= 0 and np.allclose(model.geom_rgba[geom], (0.5, 0.5, 0.5, 1.0)):
        return material
    return -1


def read_arena(model: mujoco.MjModel) -> ArenaGeometry:
    """Read the arena of a world that meets the contract: the one place its geometry is read.

    The half size is the inner face of ``SIZE_WALL``; the obstacle slots' footprints come in
    slot order; every ``wall_*`` box is kept (centre and half extents); the robot's radius and
    height come from its footprint cylinder.
    """
    def geom(name: str) -> int:
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)

    shapes, slot = [], 0
    while (g := geom(f'{OBSTACLE_PREFIX}{slot}')) >= 0:
        size = model.geom_size[g]
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER:
            shapes.append(ObstacleShape(model.geom(g).name, 'cylinder', float(size[0]),
                                        float(size[0]), float(size[1])))
        else:
            shapes.append(ObstacleShape(model.geom(g).name, 'box', float(size[0]),
                                        float(size[1]), float(size[2])))
        slot += 1
    walls = tuple(Box(*(float(v) for v in (*model.geom_pos[g], *model.geom_size[g])))
                  for g in range(model.ngeom) if model.geom(g).name.startswith(WALL_PREFIX))
    wall, robot = geom(SIZE_WALL), geom(ROBOT_GEOM)
    return ArenaGeometry(float(model.geom_pos[wall][0] - model.geom_size[wall][0]),
                         float(model.geom_size[robot][0]), tuple(shapes), walls,
                         2.0 * float(model.geom_size[robot][1]) + float(model.geom_pos[robot][2]))


def check_model(model: mujoco.MjModel, path: Path, config: SimConfig) -> list[str]:
    """Return every violation of the contract, one line each (empty: the world is valid)."""
    checker = _Checker(model, path)
    for element in REQUIRED:
        checker.require(element)
    if checker.problems:  # the other checks read the required elements
        return checker.problems
    checker.check_robot()
    checker.check_walls()
    checker.check_slots(config)
    checker.check_colliders()
    checker.check_colours()
    if not checker.problems:
        checker.check_size(config)
    return checker.problems


def _enum_name(value: object) -> str:
    """Return a MuJoCo enum value's own name: ``mjGEOM_BOX`` -> ``box``."""
    return str(getattr(value, 'name', value)).split('_', 1)[1].lower()


class _Checker:
    """Collects the violations of one compiled world."""

    def __init__(self, model: mujoco.MjModel, path: Path) -> None:
        self.m, self.path = model, path
        self.problems: list[str] = []

    def fail(self, what: str) -> None:
        self.problems.append(f'{self.path}: {what}')

    def id(self, kind: str, name: str) -> int:
        return mujoco.mj_name2id(self.m, _KINDS[kind], name)

    def require(self, element: Element) -> None:
        if self.id(element.kind, element.name) < 0:
            self.fail(f"missing {element.kind} '{element.name}': {element.rule} "
                      '(docs/worlds.md)')

    def on_body(self, kind: str, name: str, body: str) -> bool:
        owner = {'joint': self.m.jnt_bodyid, 'geom': self.m.geom_bodyid,
                 'camera': self.m.cam_bodyid}[kind][self.id(kind, name)]
        if owner != self.id('body', body):
            self.fail(f"{kind} '{name}' is on body '{self.m.body(owner).name or 'world'}', "
                      f"not on body '{body}'")
            return False
        return True

    def geom_type(self, name: str, *types: str) -> bool:
        kind = _enum_name(mujoco.mjtGeom(self.m.geom_type[self.id('geom', name)]))
        if kind not in types:
            self.fail(f"geom '{name}' is a {kind}, not a {' or a '.join(types)}")
            return False
        return True

    def collides(self, a: int, b: int) -> bool:
        m = self.m
        return bool(m.geom_contype[a] & m.geom_conaffinity[b]
                    or m.geom_contype[b] & m.geom_conaffinity[a])

    # --- the robot --------------------------------------------------------------------------
    def check_robot(self) -> None:
        m, robot = self.m, self.id('body', ROBOT)
        if m.body_parentid[robot] != 0 or m.body_mocapid[robot] >= 0:
            self.fail(f"body '{ROBOT}' must be a child of the worldbody and not mocap")
        addresses = []
        for name, kind, axis in BASE_JOINTS:
            joint = self.id('joint', name)
            self.on_body('joint', name, ROBOT)
            actual = _enum_name(mujoco.mjtJoint(m.jnt_type[joint]))
            if actual != kind or not np.allclose(m.jnt_axis[joint], axis):
                self.fail(f"joint '{name}' is a {actual} joint with axis "
                          f'{tuple(float(a) for a in m.jnt_axis[joint])}, not a {kind} joint '
                          f'with axis {axis}')
            addresses.append(int(m.jnt_qposadr[joint]))
        if addresses != list(range(addresses[0], addresses[0] + 3)):
            self.fail(f"joints {', '.join(j[0] for j in BASE_JOINTS)} must follow each other, "
                      'in this order, with no other joint on the robot between them')
        if self.on_body('geom', ROBOT_GEOM, ROBOT):
            self.geom_type(ROBOT_GEOM, 'cylinder')
        self.on_body('camera', CAMERA, ROBOT)

    # --- walls, floor, goal and slots ---------------------------------------------------------
    def check_walls(self) -> None:
        m, robot = self.m, self.id('geom', ROBOT_GEOM)
        for geom in range(m.ngeom):
            name = m.geom(geom).name
            if not name.startswith(WALL_PREFIX) or not self.geom_type(name, 'box'):
                continue
            if m.geom_bodyid[geom] != 0:
                self.fail(f"wall '{name}' must be a geom of the worldbody")
            if not np.allclose(m.geom_quat[geom], (1.0, 0.0, 0.0, 0.0)):
                self.fail(f"wall '{name}' must be axis-aligned (no rotation): give it its "
                          'extent by its size')
            if not self.collides(geom, robot):
                self.fail(f"wall '{name}' does not collide with '{ROBOT_GEOM}' (contype/"
                          'conaffinity)')
        faces = {name: side * (m.geom_pos[g][axis] - side * m.geom_size[g][axis])
                 for name, (axis, side) in OUTER_WALLS.items()
                 if m.geom_type[g := self.id('geom', name)] == mujoco.mjtGeom.mjGEOM_BOX}
        half = faces.get(SIZE_WALL, 0.0)
        if half <= 0 or any(abs(f - half) > _TOLERANCE for f in faces.values()):
            self.fail('the outer walls must enclose a square centred at the origin; their inner '
                      'faces are at ' + ', '.join(f'{n[5:]} {f:+.4g} m' for n, f in
                                                 faces.items()))
        for name in (FLOOR, GOAL):
            if self.collides(self.id('geom', name), robot):
                self.fail(f"geom '{name}' must collide with nothing (contype=\"0\" "
                          'conaffinity="0"): the robot would always be in collision')
        self.geom_type(FLOOR, 'plane')
        if self.m.body_mocapid[self.id('body', GOAL)] < 0:
            self.fail(f"body '{GOAL}' must be mocap (mocap=\"true\"): scenarios move it")
        if self.on_body('geom', GOAL, GOAL):
            self.geom_type(GOAL, 'cylinder')

    def check_slots(self, config: SimConfig) -> None:
        m, robot, slot = self.m, self.id('geom', ROBOT_GEOM), 0
        while (body := self.id('body', f'{OBSTACLE_PREFIX}{slot}')) >= 0:
            name = f'{OBSTACLE_PREFIX}{slot}'
            if m.body_mocapid[body] < 0:
                self.fail(f"body '{name}' must be mocap (mocap=\"true\"): layouts move it")
            if self.id('geom', name) < 0:
                self.fail(f"missing geom '{name}' on body '{name}': the slot's shape")
            elif self.on_body('geom', name, name) and self.geom_type(name, 'box', 'cylinder') \
                    and not self.collides(self.id('geom', name), robot):
                self.fail(f"geom '{name}' does not collide with '{ROBOT_GEOM}'")
            slot += 1
        if slot < config.num_obstacles:
            self.fail(f'{slot} obstacle slots ({OBSTACLE_PREFIX}0..{slot - 1}), but num_obstacles '
                      f'is {config.num_obstacles}: add slots or lower num_obstacles')

    def check_colliders(self) -> None:
        """Check that every geom the robot can touch is a wall or an obstacle slot."""
        m, robot = self.m, self.id('geom', ROBOT_GEOM)
        robot_body = self.id('body', ROBOT)
        for geom in range(m.ngeom):
            name = m.geom(geom).name
            if (m.geom_bodyid[geom] == robot_body or name.startswith(WALL_PREFIX)
                    or name.startswith(OBSTACLE_PREFIX) or not self.collides(geom, robot)):
                continue
            self.fail(f"geom '{name or geom}' collides with the robot but is neither a "
                      f'{WALL_PREFIX}* box nor an obstacle slot: the scenarios and the planner '
                      'would not know it (make it a wall, or set contype="0" conaffinity="0")')

    def check_colours(self) -> None:
        """Check that the goal is green and that nothing else the camera sees is."""
        m, goal = self.m, self.id('geom', GOAL)
        excess = green_excess(self.colours(goal)[0])
        if excess < GOAL_MIN_GREEN:
            self.fail(f"geom '{GOAL}' must be green: its green must exceed its red and blue by "
                      f'{GOAL_MIN_GREEN} (0-1 units), got {excess:.2f}')
        material = shown_material(m, goal)
        shared = [m.geom(g).name or str(g) for g in range(m.ngeom)
                  if g != goal and material >= 0 and shown_material(m, g) == material]
        if shared:
            self.fail(f"the goal's material is also that of geom(s) {shared}: give the goal a "
                      'material of its own (looks recolour the others)')
        for geom in range(m.ngeom):
            if geom == goal or m.geom_group[geom] >= VISIBLE_GROUPS:
                continue
            worst = max(green_excess(c) for c in self.colours(geom))
            if worst > OTHER_MAX_GREEN:
                self.fail(f"geom '{m.geom(geom).name or geom}' takes the goal's hues (green "
                          f'exceeds red and blue by {worst:.2f} > {OTHER_MAX_GREEN}): only the '
                          'goal may be green')

    def colours(self, geom: int) -> np.ndarray:
        """Return the RGB colours a geom shows: its material's (times its texture's) or its own."""
        m = self.m
        material = shown_material(m, geom)
        if material < 0:
            return m.geom_rgba[geom][None, :3]
        rgb = m.mat_rgba[material][:3]
        texture = int(m.mat_texid[material][mujoco.mjtTextureRole.mjTEXROLE_RGB])
        if texture < 0:
            return rgb[None, :]
        start, channels = int(m.tex_adr[texture]), int(m.tex_nchannel[texture])
        size = int(m.tex_width[texture] * m.tex_height[texture]) * channels
        texels = m.tex_data[start:start + size].reshape(-1, channels)[:, :3]
        return np.unique(texels, axis=0) / 255.0 * rgb

    # --- room for scenarios -----------------------------------------------------------------
    def check_size(self, config: SimConfig) -> None:
        """Check that the arena holds every obstacle slot and a start and goal far apart."""
        arena = read_arena(self.m)
        half = arena.half_size
        clear = max(arena.robot_radius + START_CLEARANCE, goal_clearance(arena, config))
        reach = 2.0 * math.sqrt(2.0) * (half - clear)
        if reach < config.min_start_goal_distance:
            self.fail(f'the arena ({2 * half:.2f} m wide) is too small for any scenario: starts '
                      f'and goals at most {max(reach, 0.0):.2f} m apart, min_start_goal_distance '
                      f'is {config.min_start_goal_distance} m')
        if config.num_obstacles == 0:
            return
        for shape in arena.shapes:
            if half - shape.bounding_radius - config.obstacle_gap <= 0:
                self.fail(f"the arena ({2 * half:.2f} m wide) is too small for obstacle slot "
                          f"'{shape.name}' with {config.obstacle_gap} m gaps")
