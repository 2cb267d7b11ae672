"""``ros2 run nav_gym policy``: a trained policy driving any ROS 2 camera (a thin adapter).

Subscribes ``camera/image_raw`` (sensor-data QoS: best effort, the newest image) and, on its own
wall-clock timer every ``period`` seconds, publishes ``cmd_vel`` (geometry_msgs/Twist, or
TwistStamped with ``cmd_vel_stamped``, stamped when it is published on the node's clock) with the
velocities of the action the policy takes on the newest image; nobody waits for it, and it
waits for nobody.  With ``cmd_vel_rate`` it repeats the current command between decisions (a
ros2_control ``diff_drive_controller`` stops after its ``cmd_vel_timeout``, 0.5 s by default).
The model, the observation and the action come from :mod:`nav_gym.policy` (no ROS there).
Without an image newer than ``image_timeout`` it publishes zero velocity; on SIGINT or SIGTERM
it publishes a zero command before it exits.

Also publishes (relative names) ``policy/decision`` (sensor_msgs/JointState, stamped with the
decided image's stamp; names and positions as :data:`nav_sim.interface.DECISION_FIELDS`: action,
cmd_vel, Q-values, image age, inference time), ``policy/observation`` (the 84x84 observation,
only while someone subscribes) and about once a second ``/diagnostics``: the decision's time
budget.  Parameters: :class:`nav_gym.policy.config.PolicyConfig` (``config/policy.yaml``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import Image, JointState
from std_srvs.srv import Trigger

from nav_gym.policy.actors import load_policy
from nav_gym.policy.config import PARAMETER_TYPES, PolicyConfig
from nav_gym.policy.controller import Command, Controller
from nav_gym.policy.process import READY_MESSAGE
from nav_sim import interface
from nav_sim.core.step_timing import StepTiming
from nav_sim.interface import DECISION_FIELDS
from nav_sim.ros import messages as ros_msgs
from nav_sim.ros import qos, sim_graph
from nav_sim.ros.node_params import declare_settings, warn_unknown_overrides, watch_settings

DYNAMIC = ('period', 'image_timeout', 'cmd_vel_rate')
WARN_PERIOD_S = 5.0
STOP_ACK_S = 1.0    # how long the final zero Twist may take to be acknowledged
SIGNAL_CHECK_S = 0.1  # how often the spin loop looks for a stop signal
DECISION_PHASES = ('inference', 'publish')


class PolicyNode(Node):
    """Publish the policy's command for the newest camera image at a fixed period."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, load the model and create the topics and the timer."""
        super().__init__(interface.POLICY_NODE_NAME, **kwargs)
        values = declare_settings(self, PolicyConfig, dynamic=DYNAMIC)
        warn_unknown_overrides(self, PARAMETER_TYPES, 'config/policy.yaml')
        self.settings = PolicyConfig(**values)
        actor, self.acting = load_policy(self.settings)
        self.controller = Controller(actor, self.acting, self._image_timeout(self.settings))
        watch_settings(self, PARAMETER_TYPES, lambda: self.settings,
                       lambda values: PolicyConfig(**values), self._apply_settings, DYNAMIC)
        self.pub_cmd = self.create_publisher(
            ros_msgs.cmd_vel_class(self.settings.cmd_vel_stamped), interface.CMD_VEL_TOPIC,
            qos.CONTROL)
        self._command = (0.0, 0.0)  # the current command's (linear, angular)
        self._repeat_timer = None
        self.pub_decision = self.create_publisher(JointState, interface.DECISION_TOPIC,
                                                  qos.DECISIONS)
        self.pub_observation = self.create_publisher(
            Image, interface.POLICY_OBSERVATION_TOPIC, qos.OBSERVATION)
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Image, interface.IMAGE_TOPIC, self._on_image, qos.SENSOR_DATA)
        # episode starts: the sim's reset events where a sim runs, else the explicit service
        self.create_subscription(DiagnosticArray, interface.EVENT_TOPIC, self._on_event,
                                 qos.OBSERVATION)
        self.create_service(Trigger, interface.POLICY_BEGIN_EPISODE_SERVICE,
                            self._on_begin_episode)
        # a wall-clock timer, even with use_sim_time: sim time moves in whole control periods,
        # and a timer on it would fire at each period's start, before that period's image
        self._timer = self.create_timer(self._period(self.settings), self._on_timer,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._set_repeat_rate(self.settings.cmd_vel_rate)
        self._timing = StepTiming(DECISION_PHASES, unit='decision')
        self._stops = 0
        self._state = ''
        self._errors_logged: set[str] = set()
        self._type_checked = False
        self.get_logger().info(
            f'{READY_MESSAGE} policy={self.settings.policy} model='
            f'{self.settings.model or "none"}, period={self._period(self.settings):.3f} s, '
            f'image_timeout={self.controller.image_timeout:.3f} s, actions (linear m/s, angular '
            f'rad/s) {self.acting.twists} from {self.acting.source}; subscribed to '
            f'{self.resolve_topic_name(interface.IMAGE_TOPIC)}, publishing '
            f'{self.resolve_topic_name(interface.CMD_VEL_TOPIC)} '
            f'({interface.cmd_vel_type(self.settings.cmd_vel_stamped)})')

    # --- parameters -----------------------------------------------------------------------
    def _period(self, settings: PolicyConfig) -> float:
        return settings.period or self.acting.control_period

    def _image_timeout(self, settings: PolicyConfig) -> float:
        return settings.image_timeout or 2.0 * self._period(settings)

    def _apply_settings(self, changes: dict[str, Any]) -> None:
        self.settings = dataclasses.replace(self.settings, **changes)
        self.controller.image_timeout = self._image_timeout(self.settings)
        self._timer.timer_period_ns = round(self._period(self.settings) * 1e9)
        self._timer.reset()
        if 'cmd_vel_rate' in changes:
            self._set_repeat_rate(self.settings.cmd_vel_rate)

    def _set_repeat_rate(self, rate: float) -> None:
        """Repeat the current command at ``rate`` Hz between decisions (0: do not)."""
        if self._repeat_timer is not None:
            self.destroy_timer(self._repeat_timer)
            self._repeat_timer = None
        if rate > 0:
            self._repeat_timer = self.create_timer(
                1.0 / rate, self._publish_command, clock=Clock(clock_type=ClockType.STEADY_TIME))

    # --- acting ---------------------------------------------------------------------------
    def _on_image(self, msg: Image) -> None:
        self.controller.on_image(msg)

    def _on_event(self, msg: DiagnosticArray) -> None:
        """Begin an episode (and the policy's memory) at a sim's reset event."""
        event = ros_msgs.parse_event(msg)
        if event is not None and event['event'] == ros_msgs.EVENT_RESET:
            seed = event.get('seed')
            since = ros_msgs.stamp_to_ns(msg.header.stamp)  # the reset frame's stamp
            self.controller.begin_episode(
                seed if isinstance(seed, int) else None,
                lambda image: ros_msgs.stamp_to_ns(image.header.stamp) < since)

    def _on_begin_episode(self, request: Any, response: Any) -> Any:
        """Begin an episode on request: a robot whose graph has no episode events."""
        self.controller.begin_episode(None)
        response.success, response.message = True, 'episode begun: the memory starts afresh'
        return response
    def _on_timer(self) -> None:
        command = self.controller.decide()
        start = time.perf_counter()
        self._command = (command.linear, command.angular)
        self._publish_command()
        self.pub_decision.publish(self._decision_msg(command))
        if command.observation is not None and self.pub_observation.get_subscription_count():
            self.pub_observation.publish(ros_msgs.image_msg(
                command.observation.transpose(1, 2, 0), command.stamp,
                command.frame_id))
        self._timing.add('publish', time.perf_counter() - start)
        self._check_cmd_vel_type()
        self._note(command)

    def _publish_command(self) -> None:
        """Publish the current command; a TwistStamped is stamped now, on the node's clock."""
        stamped = self.settings.cmd_vel_stamped
        self.pub_cmd.publish(ros_msgs.cmd_vel_msg(
            *self._command, self.get_clock().now().to_msg() if stamped else None,
            self.settings.frame_id))

    def _check_cmd_vel_type(self) -> None:
        """Log (once) a cmd_vel subscriber that takes the other type: it would never hear us."""
        if self._type_checked or self.pub_cmd.get_subscription_count():
            return
        problem = sim_graph.cmd_vel_mismatch(self, self.settings.cmd_vel_stamped)
        if problem:
            self._type_checked = True
            self.get_logger().error(problem)

    def _decision_msg(self, command: Command) -> JointState:
        stamp = command.stamp if command.stamp is not None else self.get_clock().now().to_msg()
        msg = JointState(name=list(DECISION_FIELDS),
                         position=command.values(self._stamp_age(command)))
        msg.header.stamp = stamp
        msg.header.frame_id = command.frame_id
        return msg

    def _stamp_age(self, command: Command) -> float:
        """Seconds on this node's clock (sim time with use_sim_time) since the image's stamp."""
        now = self.get_clock().now().nanoseconds
        if command.stamp is None or now <= 0:
            return math.nan
        return (now - ros_msgs.stamp_to_ns(command.stamp)) / 1e9

    def _note(self, command: Command) -> None:
        """Log a change into a stop state once (throttled); time the decision."""
        if command.stopped:
            self._stops += 1
            if command.reason == 'bad image':
                if self.controller.image_error not in self._errors_logged:
                    self._errors_logged.add(self.controller.image_error)
                    self.get_logger().error(f'{self.controller.image_error}: publishing zero '
                                            'velocity until a usable image arrives')
            elif command.reason == 'new episode':  # until the episode's first image: no gap
                pass
            elif command.reason != self._state and command.reason == 'no image':
                self.get_logger().warn(
                    f'no image on {self.resolve_topic_name(interface.IMAGE_TOPIC)} yet: '
                    'publishing zero velocity', throttle_duration_sec=WARN_PERIOD_S)
            elif command.reason != self._state:
                self.get_logger().warn(
                    f'no image newer than {self.controller.image_timeout:.3f} s on '
                    f'{self.resolve_topic_name(interface.IMAGE_TOPIC)}: publishing zero '
                    'velocity', throttle_duration_sec=WARN_PERIOD_S)
        self._state = command.reason
        timing = self._timing
        timing.add('inference', command.inference_s)
        if not math.isnan(command.image_age_s):
            timing.add('image_age', command.image_age_s)
        now = timing.step_done()
        if timing.due(now):
            report = {**timing.report(now), 'stops': self._stops}
            self._stops = 0
            self.pub_diagnostics.publish(ros_msgs.diagnostics_msg(
                f'{self.get_fully_qualified_name()}: policy decisions',
                f"{report['decisions_per_s']:.1f} decisions/s", report,
                self.get_clock().now().to_msg(), hardware_id='nav_gym'))

    def stop_robot(self) -> None:
        """Publish a zero command and wait (briefly) until its subscribers have it."""
        self._set_repeat_rate(0.0)
        self._command = (0.0, 0.0)
        self._publish_command()
        self.pub_cmd.wait_for_all_acked(Duration(seconds=STOP_ACK_S))
