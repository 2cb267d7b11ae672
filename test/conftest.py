"""Test-wide ROS isolation: a private DDS domain per test run, traffic kept on this machine."""

from __future__ import annotations

import os
import sys

# Must happen before rclpy is imported by any test module.
os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 100)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
os.environ.setdefault('MUJOCO_GL', 'egl')
