"""nav_eval: evaluation, rosbag2/MCAP recording, reports, videos, failure diagnosis and sweeps.

The commands are the top-level modules (``evaluate``, ``record``, ``report``, ``diagnose``,
``pipeline``, ``sweep``, and the sweep's children ``sweep_trial`` and ``baselines``); each is a
thin command line over the sub-packages, whose imports go one way:

    sweeps/      many seeds on Ray Tune, aggregated with rliable statistics (Sweep.md)
    reporting/   Result.md/HTML, figures, rollout videos, the diagnosis's evidence
    evaluation/  episodes of a policy on seeded scenarios, traces, which episode to diagnose
    recording/   MCAP bags of the nav_sim graph (writing with rclpy, reading with rosbags)
    analysis/    metrics, failure layers, diagnosis, anatomy, calibration, statistics (numpy)

``seeds`` holds the evaluation seed banks and ``errors`` the package's errors.
"""

from __future__ import annotations
