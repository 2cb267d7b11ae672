"""``ros2 run nav_gym policy`` (and ``nav-gym-policy``): run the policy node until a stop signal.

The node is :class:`nav_gym.policy.node.PolicyNode`; this main owns the process: SIGINT and
SIGTERM only set a flag, so the node publishes a zero Twist before it exits, and bad settings
or a bad model are one line (exit code 2 or 1).
"""

from __future__ import annotations

import os
import traceback

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from nav_gym.cli import DEBUG_ENV
from nav_gym.errors import PolicyModelError
from nav_gym.policy.node import SIGNAL_CHECK_S, PolicyNode
from nav_sim.errors import ConfigError, describe_exception
from nav_sim.ros.stop_request import StopRequest, stop_on_signals


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run nav_gym policy`` and the ``nav-gym-policy`` console script."""
    # SIGINT and SIGTERM only set a flag (no rclpy handler shuts the context down first), so
    # the zero Twist still goes out on a live context before the node exits
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    with stop_on_signals(StopRequest()) as stop:
        try:
            executor = SingleThreadedExecutor()
            node = PolicyNode()
            executor.add_node(node)
            while not stop:  # rclpy.spin(node), looking for a stop signal between callbacks
                executor.spin_once(timeout_sec=SIGNAL_CHECK_S)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except ConfigError as exc:
            print(f'policy_node: invalid configuration: {exc}')
            raise SystemExit(2) from None
        except PolicyModelError as exc:
            print(f'policy_node: {exc}')
            raise SystemExit(1) from None
        except Exception as exc:  # noqa: BLE001 - the last line of defence: one line
            if os.environ.get(DEBUG_ENV, '') not in ('', '0'):
                traceback.print_exc()
            print(f'policy_node: unexpected {describe_exception(exc)} (the robot was sent a zero '
                  f'command; {DEBUG_ENV}=1 shows the traceback)')
            raise SystemExit(1) from None
        finally:
            if node is not None:
                if rclpy.ok():
                    node.stop_robot()
                node.destroy_node()
            rclpy.try_shutdown()


if __name__ == '__main__':
    main()
