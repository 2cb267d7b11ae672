"""nav_sim: the MuJoCo world, the simulation core and the ``nav_sim`` ROS 2 node."""

from __future__ import annotations

import os

# Offscreen rendering needs no screen: EGL with Debian's Mesa (libegl1, libgl1-mesa-dri).
# Must be set before mujoco is first imported anywhere in the process.
os.environ.setdefault('MUJOCO_GL', 'egl')

__version__ = '0.1.0'
