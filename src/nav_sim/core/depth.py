"""The camera's coarse depth: a training target that travels beside the image, never in it.

Each control period the sim measures, from the camera, the depth of a ``DEPTH_SHAPE`` grid of
cells over the whole image (one ray through each cell's centre; rows top to bottom, columns
left to right, as in the image), and the episode event carries it (key ``depth``), so that an
env can put it in ``info``: the kind of target an auxiliary depth loss learns from (Mirowski
et al. 2017 predict a 4 x 16 coarse depth map of the same camera).  It is privileged state,
like the pose: never a policy input.

A cell's depth is the distance in metres along the camera's optical axis (what a depth image
holds, not the length of the ray) to the first surface its ray meets, and ``DEPTH_RANGE`` where
the ray meets nothing that close (over the walls).  The rays see every geom the camera renders:
the goal beacon, and the robot's own body at the bottom of the image.
"""

from __future__ import annotations

import math

import numpy as np

#: rows x columns of cells over the camera image (Mirowski et al.'s coarse depth map)
DEPTH_SHAPE = (4, 16)
#: metres: the depth of a cell whose ray meets nothing nearer (the rooms' diagonal is 3.4 m)
DEPTH_RANGE = 3.0
DEPTH_KEY = 'depth'  # the episode event's key and the env's ``info`` key
_DECIMALS = 3        # millimetres: the event carries text


def cell_rays(hfov_deg: float, width: int, height: int,
              shape: tuple[int, int] = DEPTH_SHAPE) -> np.ndarray:
    """Return the rays through the cells' centres in the camera frame, ``(rows * cols, 3)``.

    MuJoCo's camera frame: ``+x`` right, ``+y`` up, looking along ``-z``; each ray has a
    ``-z`` component of 1, so that a hit's distance along a unit ray divided by the ray's
    length is its depth.  The image's aspect ratio (``width`` x ``height``) sets the vertical
    field of view, as the camera's own.
    """
    rows, cols = shape
    half_w = math.tan(math.radians(hfov_deg) / 2.0)
    half_h = half_w * height / width
    x = ((np.arange(cols) + 0.5) / cols * 2.0 - 1.0) * half_w
    y = (1.0 - (np.arange(rows) + 0.5) / rows * 2.0) * half_h
    xx, yy = np.meshgrid(x, y)
    return np.stack([xx.ravel(), yy.ravel(), -np.ones(rows * cols)], axis=1)


def depth_text(depth: np.ndarray) -> str:
    """Encode a depth grid as the event's value: its cells in row order, in millimetres."""
    return ' '.join(f'{v:.{_DECIMALS}f}' for v in np.asarray(depth, dtype=np.float64).ravel())


def parse_depth(text: str, shape: tuple[int, int] = DEPTH_SHAPE) -> np.ndarray:
    """Decode the event's value into a ``shape`` float32 grid; ValueError for a wrong size."""
    values = np.array(str(text).split(), dtype=np.float32)
    if values.size != shape[0] * shape[1]:
        raise ValueError(f'a depth grid has {shape[0] * shape[1]} cells, got {values.size}')
    return values.reshape(shape)
