"""``ros2 run nav_sim sim_node`` (and ``nav-sim``): start the sim node and spin it until shutdown.

The node itself is :class:`nav_sim.ros.node.SimNode`; this main only owns the process: the
executor, lockstep or realtime spinning, and one-line errors for bad settings or worlds (exit
code 2, each line prefixed with ``ERROR_PREFIX``).
"""

from __future__ import annotations

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import uninstall_signal_handlers

from nav_sim.errors import ConfigError, ScenarioError, WorldError, WorldNotFoundError
from nav_sim.ros.lockstep import spin_lockstep
from nav_sim.ros.node import SimNode
from nav_sim.ros.process import ERROR_PREFIX
from nav_sim.ros.stop_request import StopRequest, stop_on_signals

STOP_POLL_S = 0.5  # realtime: the longest wait between looks at the stop flag


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run nav_sim sim_node`` and the ``nav-sim`` console script.

    SIGINT and SIGTERM raise nothing here.  Python's handler only notes them
    (:class:`StopRequest`), and the spinning ends on the flag.  rclpy's handlers, installed
    after it and chained to it, wake the spinning and shut the context down.  A
    KeyboardInterrupt raised while the node was being built could leave the exit code at -2,
    even when caught.
    """
    with stop_on_signals(StopRequest()) as stop:
        rclpy.init(args=args)
        node = None
        try:
            # the executor exists before the node is discoverable: a SIGTERM from a client that
            # has just seen the node must not land in the executor's constructor
            executor = SingleThreadedExecutor()
            node = SimNode()
            executor.add_node(node)
            if node.settings.mode == 'lockstep':
                spin_lockstep(node, executor, node.sub_cmd, stop=stop)  # blocks while idle
            else:
                while node.context.ok() and not stop:
                    executor.spin_once(timeout_sec=STOP_POLL_S)
        except ExternalShutdownException:
            pass
        except ConfigError as exc:
            print(f'{ERROR_PREFIX}invalid configuration: {exc}')
            raise SystemExit(2) from None
        except (WorldError, WorldNotFoundError, ScenarioError) as exc:  # one line per problem
            for line in str(exc).splitlines():
                print(f'{ERROR_PREFIX}invalid world: {line}')
            raise SystemExit(2) from None
        except Exception:
            if rclpy.ok():
                raise
            # SIGINT/SIGTERM arrived while the node was starting: a clean exit, no traceback
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
            uninstall_signal_handlers()  # before Python's own come back, outside the block


if __name__ == '__main__':
    main()
