"""Recording: rosbag2/MCAP bags of the nav_sim graph.

``recorder`` writes bags from a running graph (rclpy), ``scene`` adds the live view's topics of
an evaluated episode, ``bags`` reads bags back (rosbags only, no rclpy).
"""
