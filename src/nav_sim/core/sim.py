"""The simulation core (no ROS): reset a scenario, drive the wheels for one control period, render.

Time scales: one *physics step* is ``sim_dt`` seconds; one *control period* is ``action_repeat``
physics steps.  Collision and goal are checked after every physics step; on either event the
period stops early and the motors are stopped.  The robot base is kinematic: the e-puck's
stepper motors do not slip, so each physics step integrates the exact differential-drive motion of
the wheel speeds (an arc) and MuJoCo then computes contacts against walls and obstacles for the
new pose.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from nav_sim.core.config import TRAIN, SimConfig
from nav_sim.core.events import EVENT_COLLISION, EVENT_GOAL, EVENT_NONE
from nav_sim.core.kinematics import WheelCommand, arc_step, wheels_to_twist
from nav_sim.core.looks import draw_look
from nav_sim.core.scenarios import Scenario, build_banks, sample_scenario
from nav_sim.core.world import World
from nav_sim.errors import EpisodeNotStartedError


@dataclass(frozen=True)
class StepResult:
    """Outcome of one control period."""

    event: str
    physics_steps: int
    pose: tuple[float, float, float]
    distance: float
    done: bool
    episode_step: int
    period: int


class NavSim:
    """Scenario reset, wheel control with action repeat, goal/collision checks and rendering."""

    def __init__(self, config: SimConfig | None = None) -> None:
        """Load the world of ``config`` and build its scenario banks."""
        self.config = config or SimConfig()
        self.world = World(self.config)
        self.banks = build_banks(self.config, self.world.geometry)
        self.scenario: Scenario | None = None
        self.wheels = WheelCommand(0.0, 0.0)
        self.total_physics_steps = 0  # never reset: sim time is monotonic across episodes
        self.period = 0               # control periods since start, across episodes
        self.episode = 0
        self.episode_step = 0
        self.done = False
        self.last_event = EVENT_NONE
        self.path_length = 0.0

    # --- state ----------------------------------------------------------------------------
    @property
    def sim_time_ns(self) -> int:
        """Simulated time since start in ns (whole physics steps)."""
        return self.total_physics_steps * round(self.config.sim_dt * 1e9)

    @property
    def pose(self) -> tuple[float, float, float]:
        """Robot pose (x, y, yaw) in the world."""
        return self.world.robot_pose()

    @property
    def goal(self) -> tuple[float, float]:
        """Goal position (x, y) in the world."""
        return self.world.goal_position()

    @property
    def distance(self) -> float:
        """Straight-line distance from the robot centre to the goal in metres."""
        x, y, _ = self.pose
        gx, gy = self.goal
        return math.hypot(gx - x, gy - y)

    @property
    def twist(self) -> tuple[float, float]:
        """Current body-frame (linear, angular) velocity from the wheel speeds."""
        return wheels_to_twist(self.wheels.left, self.wheels.right, self.config)

    # --- episode control ------------------------------------------------------------------
    def reset(self, seed: int, split: str = TRAIN) -> Scenario:
        """Stop the motors, load the scenario of (seed, split) and settle; raises ScenarioError.

        With ``randomize_look`` the scenario also carries its drawn look, painted on the world.
        """
        scenario = sample_scenario(seed, split, self.banks, self.world.geometry, self.config)
        if self.config.randomize_look:
            scenario = dataclasses.replace(scenario, look=draw_look(scenario.seed,
                                                                    scenario.split))
            self.world.apply_look(scenario.look)
        self.stop()
        self.world.set_layout(scenario.layout)
        self.world.set_goal(*scenario.goal)
        self.world.set_robot_pose(*scenario.start)
        mujoco.mj_forward(self.world.model, self.world.data)
        self._run(self.config.settle_steps, check_events=False)
        self.scenario = scenario
        self.episode += 1
        self.episode_step = 0
        self.done = False
        self.last_event = EVENT_NONE
        self.path_length = 0.0
        return scenario

    def stop(self) -> None:
        """Stop the motors (the robot stays where it is)."""
        self.wheels = WheelCommand(0.0, 0.0)
        self.world.data.qvel[self.world.qvel_slice] = 0.0

    def step(self, command: WheelCommand) -> StepResult:
        """Drive with ``command`` for one control period, stopping early on goal or collision."""
        if self.scenario is None:
            raise EpisodeNotStartedError('call reset(seed, split) before step()')
        self.period += 1
        if self.done:  # the episode has ended: the motors stay stopped, time still passes
            self._run(self.config.action_repeat, check_events=False)
            return self._result(self.last_event, 0)
        self.episode_step += 1
        self.wheels = command
        event, steps = self._run(self.config.action_repeat, check_events=True)
        if event != EVENT_NONE:
            self.stop()
            self.done = True
        self.last_event = event
        return self._result(event, steps)

    def _result(self, event: str, steps: int) -> StepResult:
        return StepResult(event, steps, self.pose, self.distance, self.done, self.episode_step,
                          self.period)

    def _run(self, steps: int, check_events: bool) -> tuple[str, int]:
        """Advance up to ``steps`` physics steps of ``sim_dt`` at the current wheel speeds.

        Each step moves the base along the exact arc of the wheel speeds, then MuJoCo computes
        kinematics and contacts for the new pose.  With ``check_events`` the loop stops after
        the first step that reaches the goal (``goal_radius``) or touches an obstacle; a goal wins
        over a contact in the same step.
        Returns ``(event, steps run)``.  This is the sim's hot loop (16 steps per control
        period), so the per-period constants are hoisted and the pose lives in locals.
        """
        cfg, world = self.config, self.world
        model, data = world.model, world.data
        qpos, pose_slice = data.qpos, world.qpos_slice
        dt = cfg.sim_dt
        linear, angular = self.twist
        straight = abs(angular) < 1e-9
        radius = 0.0 if straight else linear / angular
        x, y, yaw = (float(v) for v in qpos[pose_slice])
        gx, gy = self.goal
        path_length, total = self.path_length, self.total_physics_steps
        event, done_steps = EVENT_NONE, 0
        for _ in range(steps):
            nx, ny, nyaw = arc_step(x, y, yaw, linear, angular, radius, straight, dt)
            path_length += math.hypot(nx - x, ny - y)
            x, y, yaw = nx, ny, nyaw
            qpos[pose_slice] = (x, y, yaw)
            total += 1
            data.time = total * dt
            mujoco.mj_fwdPosition(model, data)
            done_steps += 1
            if check_events:
                if math.hypot(gx - x, gy - y) <= cfg.goal_radius:
                    event = EVENT_GOAL  # success takes precedence over a contact
                    break
                if data.ncon and world.robot_in_collision():
                    event = EVENT_COLLISION
                    break
        data.qvel[world.qvel_slice] = (linear * math.cos(yaw), linear * math.sin(yaw), angular)
        self.path_length, self.total_physics_steps = path_length, total
        return event, done_steps

    # --- sensing --------------------------------------------------------------------------
    def render(self) -> np.ndarray:
        """Render the camera image (height, width, 3) uint8 RGB of the current state."""
        return self.world.render_camera()

    def depth(self) -> np.ndarray:
        """Return the camera's coarse depth of the current state (``nav_sim.core.depth``)."""
        return self.world.camera_depth()

    def close(self) -> None:
        """Free the renderer and the model."""
        self.world.close()
