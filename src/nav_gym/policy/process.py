"""Start and stop a policy node child process (what ``ros2 run nav_gym policy`` starts)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from nav_gym.policy.config import PARAMETER_TYPES
from nav_sim.core.config import convert
from nav_sim.ros.process import NodeProcess, node_command, node_ros_args

#: how the policy node's start-up log line begins (defined here, not in the node's module: a
#: process that only starts the node need not load rclpy)
READY_MESSAGE = 'nav_gym policy ready:'


def policy_command() -> list[str]:
    """Return the policy node's command (``lib/nav_gym/policy`` if installed, else ``-m``)."""
    return node_command('nav_gym', 'policy', 'nav_gym.policy_node')


class PolicyProcess(NodeProcess):
    """A policy node child process in ``namespace`` with ``params`` (``PolicyConfig``'s names).

    ``use_sim_time`` may be given too; every other value is converted to its declared type
    (``period: 1`` is sent as the double ``1.0``).
    """

    def __init__(self, namespace: str = '', params: Mapping[str, Any] | None = None,
                 quiet: bool = True, env: Mapping[str, str] | None = None) -> None:
        """Start the policy node."""
        typed = {key: value if key == 'use_sim_time' else convert(key, PARAMETER_TYPES[key],
                                                                    value)
                 for key, value in (params or {}).items()}
        super().__init__(policy_command() + node_ros_args(namespace, typed), 'policy_node',
                         READY_MESSAGE, quiet, env)
        self.namespace = namespace
