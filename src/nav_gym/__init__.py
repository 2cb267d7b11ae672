"""nav_gym: the Gymnasium environment (a ROS 2 node) and the DQN training node.

Importing the package registers ``visnav/Navigation-v0`` with Gymnasium.
"""

from __future__ import annotations

import gymnasium as gym

ENV_ID = 'visnav/Navigation-v0'

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point='nav_gym.env:NavigationEnv')
