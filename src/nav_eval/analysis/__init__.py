"""Analysis of evaluated episodes and of sweeps: pure numbers (numpy, rliable), no ROS, no torch.

``metrics`` are the task-level outcomes of episodes (success, SPL, summaries),
``failure_layers`` checks one episode layer by layer (the workshop's failure-layer model),
``diagnosis`` runs those checks in order and names the earliest suspect layer, ``anatomy``,
``calibration`` and ``looks`` look across a set's episodes, ``stats`` computes a sweep's
statistics.
"""
