from __future__ import annotations

import cv2
import numpy as np
import pytest

from nav_gym.env.observation import image_to_rgb, rgb_to_observation
from nav_gym.errors import ObservationError


def rgb_image(h: int = 96, w: int = 128) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize('encoding, conversion', [
    ('rgb8', None), ('bgr8', cv2.COLOR_RGB2BGR), ('rgba8', cv2.COLOR_RGB2RGBA),
    ('bgra8', cv2.COLOR_RGB2BGRA)])
def test_every_colour_encoding_decodes_to_the_same_rgb(encoding, conversion):
    rgb = rgb_image()
    raw = rgb if conversion is None else cv2.cvtColor(rgb, conversion)
    decoded = image_to_rgb(raw.tobytes(), 96, 128, encoding)
    assert decoded.dtype == np.uint8 and np.array_equal(decoded, rgb)


def test_row_padding_is_skipped():
    rgb = rgb_image(4, 5)
    padded = np.zeros((4, 5 * 3 + 7), np.uint8)
    padded[:, :15] = rgb.reshape(4, 15)
    assert np.array_equal(image_to_rgb(padded.tobytes(), 4, 5, 'rgb8', step=22), rgb)


def test_observation_is_channel_first_uint8_without_normalisation():
    rgb = np.zeros((96, 128, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 10, 200, 30
    obs = rgb_to_observation(rgb)
    assert obs.shape == (3, 84, 84) and obs.dtype == np.uint8 and obs.flags.c_contiguous
    assert (obs[0] == 10).all() and (obs[1] == 200).all() and (obs[2] == 30).all()


def test_resize_keeps_the_picture():
    rgb = np.zeros((96, 128, 3), np.uint8)
    rgb[:, :64] = 255  # left half white
    obs = rgb_to_observation(rgb)
    assert obs[:, :, :40].min() == 255 and obs[:, :, 44:].max() == 0


@pytest.mark.parametrize('data, h, w, enc, match', [
    (b'\x00' * 10, 2, 2, 'rgb8', 'needs 12 bytes'),
    (b'\x00' * 12, 2, 2, '16UC1', 'unsupported image encoding'),
    (b'', 0, 0, 'rgb8', 'empty'),
])
def test_malformed_images_are_rejected(data, h, w, enc, match):
    with pytest.raises(ObservationError, match=match):
        image_to_rgb(data, h, w, enc)


def test_wrong_array_is_rejected():
    with pytest.raises(ObservationError, match='uint8 RGB'):
        rgb_to_observation(np.zeros((10, 10, 3), np.float32))
