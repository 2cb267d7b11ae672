"""The ``nav_sim`` ROS 2 node (SimNode): a thin adapter around :class:`nav_sim.core.sim.NavSim`.

Publishes (relative names): ``camera/image_raw``, ``camera/camera_info``, ``odom``,
``goal_pose`` (transient local), ``episode_event`` and ``/clock``.  Subscribes ``cmd_vel``.
Services ``reset`` and ``stop`` (std_srvs/srv/Trigger).  See README.md for the lockstep protocol.
About once a second while driven it publishes ``/diagnostics``: where a control period's time
goes (``PERIOD_PHASES``).  With ``live_port`` it serves a Foxglove live view
(:mod:`nav_sim.viz.server`): camera, 3D scene, episode events and its diagnostics.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from nav_sim import interface
from nav_sim.core.config import SimConfig, normalise_split, validate_seed
from nav_sim.core.depth import DEPTH_KEY, depth_text
from nav_sim.core.events import EVENT_NONE
from nav_sim.core.kinematics import WheelCommand, twist_to_wheels
from nav_sim.core.sim import NavSim
from nav_sim.core.step_timing import StepTiming
from nav_sim.errors import NavSimError
from nav_sim.ros import messages as ros_msgs
from nav_sim.ros import qos, sim_graph
from nav_sim.ros.claim import ClaimArbiter
from nav_sim.ros.node_params import (
    declare_settings,
    given,
    warn_unknown_overrides,
    watch_settings,
)
from nav_sim.ros.process import READY_MESSAGE
from nav_sim.ros.settings import PARAMETER_TYPES, NodeConfig, realtime_period_ns

DYNAMIC = ('seed', 'split', 'realtime_rate', 'cmd_vel_timeout')
WARN_PERIOD_S = 2.0
#: where a control period's wall time goes (reported on /diagnostics): waiting for the client's
#: command, physics, camera rendering, building and publishing the messages, the live view
PERIOD_PHASES = ('wait', 'physics', 'render', 'build', 'publish', 'live')


class SimNode(Node):
    """Runs the simulation in lockstep with ``cmd_vel`` or in real time."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, load the world and create the topics and services."""
        super().__init__(interface.NODE_NAME, **kwargs)
        sim_values = declare_settings(self, SimConfig, defaults=self._world_defaults())
        node_values = declare_settings(self, NodeConfig, dynamic=DYNAMIC)
        warn_unknown_overrides(self, PARAMETER_TYPES, 'config/sim.yaml')
        self.settings = NodeConfig(**node_values)
        sim_config = SimConfig(**sim_values)
        realtime_period_ns(sim_config.ctrl_dt, self.settings.realtime_rate)  # a timer can run it
        self.sim = NavSim(sim_config)
        watch_settings(self, PARAMETER_TYPES, lambda: self.settings, self._check_settings,
                       self._apply_settings, DYNAMIC)
        self._create_interfaces()
        self._latest_cmd = WheelCommand(0.0, 0.0)
        self._latest_cmd_time = -math.inf
        self._timer = None
        self._timing = StepTiming(PERIOD_PHASES, unit='period')
        self._period_seconds = dict.fromkeys(PERIOD_PHASES, 0.0)
        self.live = self._start_live() if self.settings.live_port else None
        if self.settings.reset_on_start:
            ok, message = self.reset_episode()
            log = self.get_logger().info if ok else self.get_logger().error
            log(f'initial reset: {message}')
        if self.settings.mode == 'realtime':
            period_ns = realtime_period_ns(self.sim.config.ctrl_dt, self.settings.realtime_rate)
            self._timer = self.create_timer(period_ns / 1e9, self._on_realtime_tick)
        self.get_logger().info(
            f'{READY_MESSAGE} mode={self.settings.mode}, ctrl_dt={self.sim.config.ctrl_dt:.3f} s '
            f'({self.sim.config.action_repeat} x {self.sim.config.sim_dt} s), camera '
            f'{self.sim.config.camera_width}x{self.sim.config.camera_height} rgb8, world '
            f'{self.sim.world.path}')

    # --- set-up ---------------------------------------------------------------------------
    def _world_defaults(self) -> dict[str, Any]:
        """Return the sim parameters the chosen world sets (its ``visnav:`` settings)."""
        world = given(self, next(f for f in dataclasses.fields(SimConfig) if f.name == 'world'))
        return SimConfig.world_defaults(world if world is not None else SimConfig.world)

    def _create_interfaces(self) -> None:
        self.pub_image = self.create_publisher(Image, interface.IMAGE_TOPIC, qos.OBSERVATION)
        self.pub_info = self.create_publisher(CameraInfo, interface.CAMERA_INFO_TOPIC,
                                              qos.OBSERVATION)
        self.pub_odom = self.create_publisher(Odometry, interface.ODOM_TOPIC, qos.OBSERVATION)
        self.pub_event = self.create_publisher(DiagnosticArray, interface.EVENT_TOPIC,
                                               qos.OBSERVATION)
        self.pub_goal = self.create_publisher(PoseStamped, interface.GOAL_TOPIC, qos.LATCHED)
        self.pub_clock = (self.create_publisher(Clock, interface.CLOCK_TOPIC, qos.CLOCK)
                          if self.settings.publish_clock else None)
        cfg = self.sim.config
        self._camera_info = ros_msgs.camera_info_msg(
            cfg.camera_width, cfg.camera_height, cfg.camera_fovy_deg, ros_msgs.stamp_from_ns(0),
            self.settings.camera_frame)
        # /diagnostics as diagnostic_updater publishes it: absolute, reliable, depth 10
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.sub_cmd = self.create_subscription(
            ros_msgs.cmd_vel_class(self.settings.cmd_vel_stamped), interface.CMD_VEL_TOPIC,
            self._on_cmd_vel, qos.CONTROL)
        self.create_service(Trigger, interface.RESET_SERVICE, self._on_reset,
                            qos_profile=qos.SERVICE_REQUESTS)
        self.create_service(Trigger, interface.STOP_SERVICE, self._on_stop,
                            qos_profile=qos.SERVICE_REQUESTS)
        self.claims = ClaimArbiter(self)  # one controlling client at a time

    # --- parameters -----------------------------------------------------------------------
    def _check_settings(self, values: dict[str, Any]) -> None:
        NodeConfig(**values)
        validate_seed(values['seed'])
        normalise_split(values['split'])
        realtime_period_ns(self.sim.config.ctrl_dt, values['realtime_rate'])

    def _apply_settings(self, changes: dict[str, Any]) -> None:
        self.settings = dataclasses.replace(self.settings, **changes)
        if 'realtime_rate' in changes and self._timer is not None:
            self._timer.timer_period_ns = realtime_period_ns(self.sim.config.ctrl_dt,
                                                             self.settings.realtime_rate)
            self._timer.reset()

    # --- episodes -------------------------------------------------------------------------
    def reset_episode(self) -> tuple[bool, str]:
        """Load the scenario of the current (seed, split); publish its first observation."""
        try:
            seed = validate_seed(self.settings.seed)
            split = normalise_split(self.settings.split)
            scenario = self.sim.reset(seed, split)
        except NavSimError as exc:
            return False, f'reset failed: {exc}'
        self._latest_cmd = WheelCommand(0.0, 0.0)
        stamp = ros_msgs.stamp_from_ns(self.sim.sim_time_ns)
        self.pub_goal.publish(ros_msgs.goal_msg(scenario.goal, stamp, self.settings.odom_frame))
        if self.live is not None:
            self._live_scene.reset(scenario.to_dict(), self.sim.pose)
        self._publish_period(ros_msgs.EVENT_RESET, physics_steps=self.sim.config.settle_steps)
        # a reset is between control periods: the next period counts it as waiting for the
        # client, so its publishing must not count again in that period's phases
        self._period_seconds.update(dict.fromkeys(self._period_seconds, 0.0))
        description = scenario.to_dict()
        description.update(episode=self.sim.episode, period=self.sim.period,
                           stamp_ns=self.sim.sim_time_ns)
        return True, json.dumps(description)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        if sim_graph.sim_count(self) > 1:  # another sim here: a client would mix two worlds
            response.success = False
            response.message = sim_graph.conflict_message(self, sim_graph.sim_nodes(self))
        else:
            response.success, response.message = self.reset_episode()
            if response.success and self._timer is not None:
                self._timer.reset()  # realtime: the episode's first period is a whole period
        if not response.success:
            self.get_logger().error(response.message)
        return response

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        self.sim.stop()
        self._latest_cmd = WheelCommand(0.0, 0.0)
        response.success = True
        response.message = json.dumps({'wheels': [self.sim.wheels.left, self.sim.wheels.right],
                                       'period': self.sim.period})
        return response

    # --- control --------------------------------------------------------------------------
    def command_from_twist(self, msg: Twist) -> WheelCommand:
        """Wheel speeds for a Twist; non-finite values stop the robot, huge ones saturate."""
        try:
            command = twist_to_wheels(float(msg.linear.x), float(msg.angular.z),
                                      self.sim.config)
        except ValueError as exc:
            self.get_logger().warn(f'cmd_vel rejected ({exc}); motors stopped',
                                   throttle_duration_sec=WARN_PERIOD_S)
            return WheelCommand(0.0, 0.0)
        if command.saturated:
            self.get_logger().warn(
                f'cmd_vel (linear={msg.linear.x:.3g}, angular={msg.angular.z:.3g}) exceeds the '
                f'wheel limit {self.sim.config.max_wheel_speed} rad/s; scaled down',
                throttle_duration_sec=WARN_PERIOD_S)
        return command

    def _on_cmd_vel(self, msg: Twist | TwistStamped) -> None:
        command = self.command_from_twist(ros_msgs.twist_of(msg))
        if self.settings.mode == 'realtime':
            self._latest_cmd, self._latest_cmd_time = command, time.monotonic()
            return
        if self.sim.scenario is None:
            self.get_logger().warn('cmd_vel ignored: no episode loaded; call the reset service',
                                   throttle_duration_sec=WARN_PERIOD_S)
            return
        self._advance(command)

    def _on_realtime_tick(self) -> None:
        if self.sim.scenario is None:
            return
        if time.monotonic() - self._latest_cmd_time > self.settings.cmd_vel_timeout:
            self._latest_cmd = WheelCommand(0.0, 0.0)
        self._advance(self._latest_cmd)

    def _advance(self, command: WheelCommand) -> None:
        start = time.perf_counter()
        seconds = self._period_seconds
        seconds['wait'] += self._timing.since_last_step(start)
        result = self.sim.step(command)
        if result.done and self.settings.mode == 'realtime':
            self._latest_cmd = WheelCommand(0.0, 0.0)
        seconds['physics'] += time.perf_counter() - start
        if self.live is not None:
            self._live_scene.step(result.pose)
        self._publish_period(result.event, physics_steps=result.physics_steps)
        self._period_done()

    # --- publishing -----------------------------------------------------------------------
    def _publish_period(self, event: str, physics_steps: int) -> None:
        """Publish every message of one control period with the same sim-time stamp.

        The small messages go first so a client can process them while the camera renders; a
        message nobody subscribes to is not built.
        """
        sim, settings, send = self.sim, self.settings, self._send
        stamp = ros_msgs.stamp_from_ns(sim.sim_time_ns)
        pose, twist = sim.pose, sim.twist
        # the event and the image are always published: a client pairs them to make a frame
        event_msg = send(self.pub_event, lambda: ros_msgs.event_msg(
            event or EVENT_NONE, self._event_values(physics_steps, pose, twist), stamp))
        if self.pub_odom.get_subscription_count():
            send(self.pub_odom, lambda: ros_msgs.odometry_msg(
                pose, twist, stamp, settings.odom_frame, settings.base_frame))
        if self.pub_clock is not None and self.pub_clock.get_subscription_count():
            send(self.pub_clock, lambda: ros_msgs.clock_msg(stamp))
        if self.pub_info.get_subscription_count():
            self._camera_info.header.stamp = stamp
            send(self.pub_info, lambda: self._camera_info)
        start = time.perf_counter()
        rgb = sim.render()
        self._period_seconds['render'] += time.perf_counter() - start
        send(self.pub_image, lambda: ros_msgs.image_msg(rgb, stamp, settings.camera_frame))
        if self.live is not None:
            start = time.perf_counter()
            self._log_live(event_msg, rgb, event == ros_msgs.EVENT_RESET)
            self._period_seconds['live'] += time.perf_counter() - start

    def _send(self, publisher: Any, build: Any) -> Any:
        """Build a message and publish it, timing both; returns the message."""
        start = time.perf_counter()
        msg = build()
        built = time.perf_counter()
        publisher.publish(msg)
        seconds = self._period_seconds
        seconds['build'] += built - start
        seconds['publish'] += time.perf_counter() - built
        return msg

    # --- time budget (/diagnostics) and live view -------------------------------------------
    def _period_done(self) -> None:
        """Close a control period's timing; about once a second publish /diagnostics.

        Phases are accumulated only within control periods (a reset between periods counts as
        waiting for the client), so the phases add up to the period's wall time.
        """
        timing, seconds = self._timing, self._period_seconds
        for phase, value in seconds.items():
            timing.add(phase, value)
            seconds[phase] = 0.0
        now = timing.step_done()
        if timing.due(now):
            self._publish_diagnostics(timing.report(now))

    def _publish_diagnostics(self, report: dict[str, float]) -> None:
        msg = ros_msgs.diagnostics_msg(
            f'{self.get_fully_qualified_name()}: control period',
            f"{report['periods_per_s']:.1f} periods/s", report,
            ros_msgs.stamp_from_ns(self.sim.sim_time_ns), hardware_id='nav_sim')
        self.pub_diagnostics.publish(msg)
        if self.live is not None:
            from nav_sim.viz import topics as live_topics
            self.live.log_cdr(live_topics.DIAGNOSTICS_TOPIC, lambda: serialize_message(msg),
                              self.sim.sim_time_ns)

    def _start_live(self) -> Any:
        # imported only with the live view on (rosbags' typestore, the Foxglove SDK)
        from nav_sim.viz import topics as live_topics
        from nav_sim.viz.server import EpisodeScene, LiveView
        live = LiveView(self.settings.live_port, live_topics.SIM_TOPICS,
                        name=f'visnav {self.get_fully_qualified_name()}')
        self._live_scene = EpisodeScene(live_topics.ArenaScene.from_world(
            self.sim.world, self.settings.odom_frame))
        if self.sim.scenario is not None:
            self._live_scene.reset(self.sim.scenario.to_dict(), self.sim.pose)
        self.get_logger().info(f'live view: open {live.url} in Foxglove '
                               '(layout: share/nav_sim/config/foxglove/visnav.json)')
        return live

    def _log_live(self, event_msg: DiagnosticArray, rgb: Any, new_episode: bool) -> None:
        """Send what a viewer subscribes to: camera, event, scene and robot."""
        from nav_sim.viz import topics as live_topics
        live, stamp_ns = self.live, self.sim.sim_time_ns
        live.log(live_topics.CAMERA_TOPIC,
                 lambda: live_topics.image(rgb, stamp_ns, self.settings.camera_frame), stamp_ns)
        live.log_cdr(live_topics.EVENT_TOPIC, lambda: serialize_message(event_msg), stamp_ns)
        self._live_scene.log(live, stamp_ns, new_episode)

    def _event_values(self, physics_steps: int, pose: tuple[float, float, float],
                      twist: tuple[float, float]) -> dict[str, Any]:
        sim, scenario = self.sim, self.sim.scenario
        return {
            'period': sim.period, 'episode': sim.episode, 'episode_step': sim.episode_step,
            'seed': scenario.seed if scenario else -1,
            'split': scenario.split if scenario else '',
            'distance': sim.distance, 'physics_steps': physics_steps, 'done': sim.done,
            'x': pose[0], 'y': pose[1], 'yaw': pose[2], 'linear': twist[0], 'angular': twist[1],
            'wheel_left': sim.wheels.left, 'wheel_right': sim.wheels.right,
            'path_length': sim.path_length,
            # privileged, as the pose: a training target (nav_sim.core.depth), never an input
            DEPTH_KEY: depth_text(sim.depth()),
        }

    def destroy_node(self) -> None:
        """Stop the live view and release the renderer, then destroy the node."""
        if self.live is not None:
            self.live.close()
            self.live = None
        self.sim.close()
        super().destroy_node()

