"""Camera image -> policy observation, exactly as the workshop describes (no ROS imports).

OpenCV colour conversion to RGB -> resize to 84x84 -> channel-first (3, 84, 84) uint8, with no
extra normalisation (SB3's CnnPolicy scales images itself).
"""

from __future__ import annotations

import cv2
import numpy as np

from nav_gym.errors import ObservationError

OBS_SIZE = 84
OBS_SHAPE = (3, OBS_SIZE, OBS_SIZE)

# encoding -> (channels, OpenCV conversion to RGB or None)
_ENCODINGS: dict[str, tuple[int, int | None]] = {
    'rgb8': (3, None),
    'bgr8': (3, cv2.COLOR_BGR2RGB),
    'rgba8': (4, cv2.COLOR_RGBA2RGB),
    'bgra8': (4, cv2.COLOR_BGRA2RGB),
    'mono8': (1, cv2.COLOR_GRAY2RGB),
}


def image_to_rgb(data: bytes | memoryview | np.ndarray, height: int, width: int, encoding: str,
                 step: int | None = None) -> np.ndarray:
    """Decode a raw 8-bit image buffer to an (H, W, 3) uint8 RGB array."""
    if encoding not in _ENCODINGS:
        raise ObservationError(f'unsupported image encoding {encoding!r}; expected one of '
                               f'{sorted(_ENCODINGS)}')
    channels, conversion = _ENCODINGS[encoding]
    if height <= 0 or width <= 0:
        raise ObservationError(f'empty image ({width}x{height})')
    row = width * channels
    step = step or row
    flat = np.frombuffer(data, dtype=np.uint8)
    if step < row or flat.size != step * height:
        raise ObservationError(f'{encoding} image {width}x{height} (step {step}) needs '
                               f'{step * height} bytes, got {flat.size}')
    pixels = flat.reshape(height, step)[:, :row].reshape(height, width, channels)
    if conversion is None:
        return pixels
    return cv2.cvtColor(pixels, conversion)


def rgb_to_observation(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB -> (3, 84, 84) uint8, channel-first."""
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ObservationError(f'expected an (H, W, 3) uint8 RGB image, got {rgb.shape} '
                               f'{rgb.dtype}')
    resized = cv2.resize(rgb, (OBS_SIZE, OBS_SIZE), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(resized.transpose(2, 0, 1))


def image_msg_to_observation(msg: object) -> tuple[np.ndarray, np.ndarray]:
    """Convert a sensor_msgs/Image (duck-typed) to (observation, native RGB image)."""
    rgb = image_to_rgb(msg.data, msg.height, msg.width, msg.encoding, msg.step)  # type: ignore[attr-defined]
    return rgb_to_observation(rgb), rgb
