"""nav_sim's core, free of ROS: the world, its contract, scenarios, looks, the sim and the planner.

Also the settings (``config``), kinematics, event names and step timing.  Nothing under this
package imports rclpy.  MuJoCo is imported only by ``world``, ``contract`` and ``sim``: the
planner, the scenarios and the geometry run without it.
"""
