"""nav_eval: deterministic evaluation, rosbag2/MCAP recording, reports and failure diagnosis."""

from __future__ import annotations
