"""nav_gym: the Gymnasium env over the sim node, DQN training, and the policy node.

``env/`` is the env (a ROS 2 client of nav_sim), its reward as a pure function, observation,
actions, checks and live view; ``training/`` the training configuration, the learner (SB3
subclasses), the run directory and the trainer; ``policy/`` a trained policy outside the env:
its actors, controller, servo baseline and ROS node.  The top level holds the commands (thin
mains: train, validate, episode, policy_node), the command-line helpers and the errors, and
two modules that keep the old paths of pickled classes (``learner``, ``train_config``).

Importing the package registers ``visnav/Navigation-v0`` with Gymnasium.
"""

from __future__ import annotations

import gymnasium as gym

ENV_ID = 'visnav/Navigation-v0'

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point='nav_gym.env.navigation:NavigationEnv')
