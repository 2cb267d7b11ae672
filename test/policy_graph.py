"""A camera and a listener around a policy node under test (its tests and the export's)."""

from __future__ import annotations

import time
from typing import Any

from geometry_msgs.msg import Twist
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Image, JointState

from helpers import wait_until
from nav_sim import interface
from nav_sim.ros import qos
from nav_sim.ros.bare import own_node

DEEP = QoSProfile(depth=100, reliability=qos.DECISIONS.reliability)


class Graph:
    """A camera and a listener: publishes images, collects the policy node's messages.

    ``twists`` are the ``cmd_vel`` messages (of ``cmd_vel_type``), ``received`` the wall-clock
    time each arrived.
    """

    def __init__(self, namespace: str, image_topic: str = interface.IMAGE_TOPIC,
                 cmd_vel_type: type = Twist) -> None:
        self.context, self.node = own_node('policy_test', namespace)
        self.camera = self.node.create_publisher(Image, image_topic, qos.OBSERVATION)
        self.twists: list[Any] = []
        self.received: list[float] = []
        self.decisions: list[JointState] = []
        self.observations: list[Image] = []
        self.node.create_subscription(cmd_vel_type, interface.CMD_VEL_TOPIC, self._on_cmd_vel,
                                      QoSProfile(depth=100))
        self.node.create_subscription(JointState, interface.DECISION_TOPIC,
                                      self.decisions.append, DEEP)
        self.node.create_subscription(Image, interface.POLICY_OBSERVATION_TOPIC,
                                      self.observations.append, DEEP)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _on_cmd_vel(self, msg: Any) -> None:
        self.twists.append(msg)
        self.received.append(time.time())

    def spin_until(self, done, timeout: float, what: str, details=None):  # noqa: ANN201
        def spun():  # noqa: ANN202
            self.executor.spin_once(timeout_sec=0.02)
            return done()
        return wait_until(spun, timeout, what, interval=0, details=details)

    def connected(self, timeout: float = 60.0, details=None) -> None:  # noqa: ANN001
        """Wait until the policy node is up: it subscribes the camera and publishes decisions."""
        self.spin_until(lambda: self.camera.get_subscription_count() > 0 and self.decisions,
                        timeout, 'the policy node', details)

    def publish(self, msg: Image) -> None:
        self.camera.publish(msg)

    def stream(self, msg: Image, done, timeout: float, what: str, details=None):  # noqa: ANN201
        """Publish ``msg`` again and again, as a camera would, until ``done()``; return that.

        For a wait on a decision: the node stops on an image older than ``image_timeout`` (two
        periods by default, 0.1 s at a 0.05-s period), which one image published once outlives
        on a loaded machine.  Not for a node with memory, whose history each copy would enter.
        """
        def shown():  # noqa: ANN202
            self.publish(msg)
            return done()
        return self.spin_until(shown, timeout, what, details)

    def decision(self, msg: JointState) -> dict[str, float]:
        return dict(zip(msg.name, msg.position, strict=True))

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()
