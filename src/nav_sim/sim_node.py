"""``nav_sim`` ROS 2 node: a thin adapter around :class:`nav_sim.sim.NavSim`.

Publishes (relative names): ``camera/image_raw``, ``camera/camera_info``, ``odom``,
``goal_pose`` (transient local), ``episode_event`` and ``/clock``.  Subscribes ``cmd_vel``.
Services ``reset`` and ``stop`` (std_srvs/srv/Trigger).  See README.md for the lockstep protocol.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from nav_sim import qos, ros_msgs
from nav_sim.config import NodeConfig, SimConfig, normalise_split, validate_seed
from nav_sim.errors import ConfigError, NavSimError
from nav_sim.sim import EVENT_NONE, NavSim, WheelCommand, twist_to_wheels

DYNAMIC = ('seed', 'split', 'realtime_rate', 'cmd_vel_timeout')
WARN_PERIOD_S = 2.0
IDLE_WAIT_NS = 2_000_000   # lockstep: look at timers and the rest after 2 ms without a command
SERVICE_EVERY = 16         # ... and at least every 16 commands


class SimNode(Node):
    """Runs the simulation in lockstep with ``cmd_vel`` or in real time."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('sim_node', **kwargs)
        sim_values = self._declare(SimConfig, read_only=True)
        node_values = self._declare(NodeConfig, read_only=False)
        self.settings = NodeConfig(**node_values)
        self.sim = NavSim(SimConfig(**sim_values))
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._create_interfaces()
        self._latest_cmd = WheelCommand(0.0, 0.0)
        self._latest_cmd_time = -math.inf
        self._timer = None
        if self.settings.reset_on_start:
            ok, message = self.reset_episode()
            log = self.get_logger().info if ok else self.get_logger().error
            log(f'initial reset: {message}')
        if self.settings.mode == 'realtime':
            period = self.sim.config.ctrl_dt / self.settings.realtime_rate
            self._timer = self.create_timer(period, self._on_realtime_tick)
        self.get_logger().info(
            f'nav_sim ready: mode={self.settings.mode}, ctrl_dt={self.sim.config.ctrl_dt:.3f} s '
            f'({self.sim.config.action_repeat} x {self.sim.config.sim_dt} s), camera '
            f'{self.sim.config.camera_width}x{self.sim.config.camera_height} rgb8, world '
            f'{self.sim.world.path}')

    # --- set-up ---------------------------------------------------------------------------
    def _declare(self, config_type: type, read_only: bool) -> dict[str, Any]:
        values = {}
        for field in dataclasses.fields(config_type):
            fixed = read_only or (config_type is NodeConfig and field.name not in DYNAMIC)
            descriptor = ParameterDescriptor(description=field.metadata['help'],
                                             read_only=fixed)
            values[field.name] = self.declare_parameter(field.name, field.default,
                                                        descriptor).value
        return values

    def _create_interfaces(self) -> None:
        self.pub_image = self.create_publisher(Image, 'camera/image_raw', qos.OBSERVATION)
        self.pub_info = self.create_publisher(CameraInfo, 'camera/camera_info', qos.OBSERVATION)
        self.pub_odom = self.create_publisher(Odometry, 'odom', qos.OBSERVATION)
        self.pub_event = self.create_publisher(DiagnosticArray, 'episode_event', qos.OBSERVATION)
        self.pub_goal = self.create_publisher(PoseStamped, 'goal_pose', qos.LATCHED)
        self.pub_clock = (self.create_publisher(Clock, '/clock', qos.CLOCK)
                          if self.settings.publish_clock else None)
        cfg = self.sim.config
        self._camera_info = ros_msgs.camera_info_msg(
            cfg.camera_width, cfg.camera_height, cfg.camera_fovy_deg, ros_msgs.stamp_from_ns(0),
            self.settings.camera_frame)
        self.sub_cmd = self.create_subscription(Twist, 'cmd_vel', self._on_cmd_vel, qos.CONTROL)
        self.create_service(Trigger, 'reset', self._on_reset)
        self.create_service(Trigger, 'stop', self._on_stop)

    # --- parameters -----------------------------------------------------------------------
    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        values = dataclasses.asdict(self.settings)
        values.update({p.name: p.value for p in params if p.name in values})
        try:
            NodeConfig(**values)
            validate_seed(values['seed'])
            normalise_split(values['split'])
        except (NavSimError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        changes = {p.name: p.value for p in params if p.name in DYNAMIC}
        if changes:
            self.settings = dataclasses.replace(self.settings, **changes)
        if 'realtime_rate' in changes and self._timer is not None:
            period = self.sim.config.ctrl_dt / self.settings.realtime_rate
            self._timer.timer_period_ns = int(period * 1e9)
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
        self._publish_period(ros_msgs.EVENT_RESET, physics_steps=self.sim.config.settle_steps)
        description = scenario.to_dict()
        description.update(episode=self.sim.episode, period=self.sim.period,
                           stamp_ns=self.sim.sim_time_ns)
        return True, json.dumps(description)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        response.success, response.message = self.reset_episode()
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

    def _on_cmd_vel(self, msg: Twist) -> None:
        command = self.command_from_twist(msg)
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
        result = self.sim.step(command)
        if result.done and self.settings.mode == 'realtime':
            self._latest_cmd = WheelCommand(0.0, 0.0)
        self._publish_period(result.event, physics_steps=result.physics_steps)

    # --- publishing -----------------------------------------------------------------------
    def _publish_period(self, event: str, physics_steps: int) -> None:
        """Publish every message of one control period with the same sim-time stamp.

        The small messages go first so a client can process them while the camera renders; a
        message nobody subscribes to is not built.
        """
        sim, settings = self.sim, self.settings
        stamp = ros_msgs.stamp_from_ns(sim.sim_time_ns)
        pose, twist = sim.pose, sim.twist
        # the event and the image are always published: a client pairs them to make a frame
        self.pub_event.publish(ros_msgs.event_msg(event or EVENT_NONE,
                                                  self._event_values(physics_steps, pose, twist),
                                                  stamp))
        if self.pub_odom.get_subscription_count():
            self.pub_odom.publish(ros_msgs.odometry_msg(pose, twist, stamp, settings.odom_frame,
                                                        settings.base_frame))
        if self.pub_clock is not None and self.pub_clock.get_subscription_count():
            self.pub_clock.publish(ros_msgs.clock_msg(stamp))
        if self.pub_info.get_subscription_count():
            self._camera_info.header.stamp = stamp
            self.pub_info.publish(self._camera_info)
        self.pub_image.publish(ros_msgs.image_msg(sim.render(), stamp, settings.camera_frame))

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
        }

    def destroy_node(self) -> None:
        self.sim.close()
        super().destroy_node()


def spin_lockstep(node: SimNode, executor: SingleThreadedExecutor) -> None:
    """Serve ``cmd_vel`` from a bare wait set (as ``rclpy.wait_for_message`` does) and let the
    executor handle services, parameters and the rest.

    The generic executor costs about a third of a millisecond per callback, as much as the
    sim's step and render together; lockstep commands are the hot path, so they skip it.  The
    wait set also holds the node's services, so a ``reset``/``stop`` request wakes the loop at
    once (episode boundaries are on the training path too); anything else (timers, parameter
    events) is looked at after ``IDLE_WAIT_NS`` without a command.
    """
    context = node.context
    sub = node.sub_cmd
    services = list(node.services)
    wait_set = _rclpy.WaitSet(1, 0, 0, 0, len(services), 0, context.handle)
    served = 0
    while context.ok():
        wait_set.clear_entities()
        wait_set.add_subscription(sub.handle)
        for service in services:
            wait_set.add_service(service.handle)
        wait_set.wait(IDLE_WAIT_NS)
        taken = None
        if sub.handle.pointer in wait_set.get_ready_entities('subscription'):
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
        if taken is not None:
            node._on_cmd_vel(taken[0])
            served += 1
        if taken is None or served % SERVICE_EVERY == 0:
            executor.spin_once(timeout_sec=0.0)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run nav_sim sim_node`` and the ``nav-sim`` console script."""
    rclpy.init(args=args)
    node = None
    try:
        # the executor exists before the node is discoverable: a SIGTERM from a client that
        # has just seen the node must not land in the executor's constructor
        executor = SingleThreadedExecutor()
        node = SimNode()
        executor.add_node(node)
        if node.settings.mode == 'lockstep':
            spin_lockstep(node, executor)
        else:
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ConfigError as exc:
        print(f'sim_node: invalid configuration: {exc}')
        raise SystemExit(2) from None
    except Exception:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM arrived while the node was starting: a clean exit, no traceback
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
