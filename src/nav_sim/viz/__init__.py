"""The Foxglove live view, free of rclpy: topics and messages, the server, the layout, a client.

``topics`` builds the ROS 2 messages that the view and the evaluation bags show (with rosbags'
CDR, no rclpy); ``server`` serves them over the Foxglove SDK's WebSocket; ``layout`` builds the
shipped layout; ``client`` is a headless viewer for tests and checks; ``options`` is the
commands' ``--live [PORT]``.
"""
