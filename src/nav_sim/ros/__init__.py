"""nav_sim's ROS 2 adapter: the node, settings, client, messages, QoS, lockstep and processes.

``node`` (SimNode) adapts :class:`nav_sim.core.sim.NavSim` to the graph; ``client`` is the
lockstep client the env uses; ``messages`` converts between the core and standard messages;
``process`` starts and stops node processes; ``stop_request`` turns SIGINT/SIGTERM into a flag.
"""
