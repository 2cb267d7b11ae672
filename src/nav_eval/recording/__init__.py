"""Recording: rosbag2/MCAP bags of the nav_sim graph.

``recorder`` writes bags from a running graph (rclpy) with the ``topics`` it subscribes to and
each message's bag time from ``timestamps`` (pure), ``session`` records until told to stop,
``scene`` adds the live view's topics of an evaluated episode, ``bags`` reads bags back
(rosbags only, no rclpy).
"""
