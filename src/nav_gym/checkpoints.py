"""Checkpoint file names of a training run (no ROS, no torch).

The one definition shared by training, evaluation and the report.
"""

from __future__ import annotations

import re
from pathlib import Path

CHECKPOINT_RE = re.compile(r'dqn_(\d+)_steps\.zip$')


def checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """Return (steps, path) of the run's ``checkpoints/dqn_<steps>_steps.zip``, oldest first."""
    found = []
    for path in (Path(run_dir) / 'checkpoints').glob('dqn_*_steps.zip'):
        match = CHECKPOINT_RE.search(path.name)
        if match:
            found.append((int(match.group(1)), path))
    return sorted(found)
