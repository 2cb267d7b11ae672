"""A trained policy outside the env: settings, actors, the controller, the servo and the ROS node.

``config`` (PolicyConfig), ``actors`` (the one acting protocol and its DQN and servo actors,
loaded from a run), ``controller`` (newest image in, command out), ``servo`` (the image-only
baseline), ``process`` (a policy node child process) and ``node`` (PolicyNode, the thin ROS
adapter that ``ros2 run nav_gym policy`` starts).
"""
