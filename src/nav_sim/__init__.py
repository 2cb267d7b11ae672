"""nav_sim: the MuJoCo simulation, its ROS 2 node and the Foxglove live view.

``core/`` is the simulation without ROS: settings, world files and their contract, the MuJoCo
world, scenario banks and looks, kinematics, event names, the sim and the planner.  ``viz/`` is
the live view (topics, server, layout, client; no rclpy).  ``ros/`` is the ROS 2 adapter: the
node, its settings, the lockstep client, message conversions, QoS, processes.  The top level
holds what every layer shares (``interface``: the graph's names and types; ``errors``;
``paths``: the ament index) and the thin mains ``sim_node`` and ``demo``.
"""

from __future__ import annotations

import os

# Offscreen rendering needs no screen: EGL with Debian's Mesa (libegl1, libgl1-mesa-dri).
# Must be set before mujoco is first imported anywhere in the process.
os.environ.setdefault('MUJOCO_GL', 'egl')

__version__ = '0.1.0'
