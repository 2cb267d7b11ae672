"""nav_gym: the Gymnasium environment (a ROS 2 node) and the DQN training node."""

from __future__ import annotations
