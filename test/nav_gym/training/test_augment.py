"""The learner's augmentations of sampled observations: random shifts and colour jitter."""

from __future__ import annotations

import math

import pytest
import torch as th

from nav_gym.training.augment import (
    HUE_DEGREES,
    colour_transforms,
    random_colour,
    random_shift,
)
from nav_sim.core.looks import BANDS, HUE_SPAN, green_excess


# --- random shifts (DrQ) ------------------------------------------------------------------------
def test_a_shift_of_0_pixels_is_the_identity():
    images = th.randint(0, 256, (5, 3, 84, 84), dtype=th.uint8)
    assert random_shift(images, 0) is images


def test_a_shift_keeps_shape_and_dtype_and_one_seed_gives_one_result():
    images = th.randint(0, 256, (8, 3, 84, 84), dtype=th.uint8)
    first = random_shift(images, 4, th.Generator().manual_seed(7))
    assert first.shape == images.shape and first.dtype == th.uint8
    assert th.equal(first, random_shift(images, 4, th.Generator().manual_seed(7)))
    assert not th.equal(first, random_shift(images, 4, th.Generator().manual_seed(8)))


def test_a_shift_is_replicate_padding_then_a_crop_per_image():
    images = th.arange(2 * 1 * 6 * 6, dtype=th.float32).reshape(2, 1, 6, 6)
    generator = th.Generator().manual_seed(3)
    shifted = random_shift(images, 2, generator)
    padded = th.nn.functional.pad(images, (2, 2, 2, 2), mode='replicate')
    found = []
    for i in range(2):  # each image is one of the 25 crops of its own padded image
        crops = [(dy, dx) for dy in range(5) for dx in range(5)
                 if th.equal(shifted[i], padded[i, :, dy:dy + 6, dx:dx + 6])]
        assert len(crops) == 1
        found.append(crops[0])
    assert found != [(2, 2), (2, 2)]  # not both left in place


# --- colour jitter (RAD) ------------------------------------------------------------------------
def _hue(rgb: th.Tensor) -> th.Tensor:
    """Return the angle of colours about the grey axis (radians): the hue a rotation turns."""
    r, g, b = rgb.unbind(-1)
    return th.atan2(math.sqrt(3) * (g - b), 2 * r - g - b)


def test_a_colour_jitter_of_strength_0_is_the_identity_and_a_bad_one_an_error():
    images = th.randint(0, 256, (5, 3, 84, 84), dtype=th.uint8)
    assert random_colour(images, 0.0) is images
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match='strength'):
            random_colour(images, bad)
    with pytest.raises(ValueError, match='frames'):
        random_colour(images, 0.2, frames=2)


def test_each_part_of_the_jitter_stays_within_its_strength():
    strength, n = 0.2, 2000
    matrices, contrast, brightness = colour_transforms(n, strength, th.Generator().manual_seed(1))
    for factor in (contrast, brightness):
        assert factor.min() >= 1 - strength and factor.max() <= 1 + strength
        assert factor.max() - factor.min() > 1.8 * strength  # the probe: it spans the range
    grey = th.ones(3)
    assert th.allclose(matrices @ grey, (brightness * contrast)[:, None] * grey, atol=1e-5)
    # columns sum to brightness x contrast too: the image's mean grey is scaled, not shifted
    assert th.allclose(matrices.sum(dim=1), (brightness * contrast)[:, None].expand(n, 3),
                       atol=1e-5)
    red = th.tensor([1.0, 0.0, 0.0])  # a pure chroma: the turn of its hue is the hue jitter
    turned = (_hue(matrices @ red) - _hue(red)).abs()
    limit = math.radians(strength * HUE_DEGREES)
    assert turned.max() <= limit + 1e-5 and turned.max() > 0.95 * limit
    # saturation: the chroma's length over brightness x contrast, within [1 - s, 1 + s]
    chroma = (matrices @ red) - (matrices @ red).mean(-1, keepdim=True)
    ratio = chroma.norm(dim=-1) / (red - red.mean()).norm() / (brightness * contrast)
    assert ratio.min() >= 1 - strength - 1e-5 and ratio.max() <= 1 + strength + 1e-5


def test_strength_02_turns_the_hue_by_one_band_of_the_looks_palettes():
    assert 0.2 * HUE_DEGREES == HUE_SPAN / BANDS


def test_the_frames_of_a_stack_share_one_jitter_and_the_action_planes_are_kept():
    frame = th.randint(0, 256, (4, 3, 8, 8), dtype=th.uint8)
    planes = th.zeros((4, 3, 8, 8), dtype=th.uint8)
    planes[:, 1] = 255
    stacks = th.cat([frame, frame, planes], dim=1)  # a 2-frame stack, its frames alike
    out = random_colour(stacks, 0.5, frames=2, generator=th.Generator().manual_seed(2))
    assert out.shape == stacks.shape and out.dtype == th.float32
    assert th.equal(out[:, :3], out[:, 3:6])
    assert not th.allclose(out[:, :3], frame.float(), atol=1.0)  # the probe: it jittered
    assert th.equal(out[:, 6:], planes.float())
    assert out.min() >= 0 and out.max() <= 255
    again = random_colour(stacks, 0.5, frames=2, generator=th.Generator().manual_seed(2))
    assert th.equal(out, again)


def test_the_jitter_is_the_drawn_transform_about_the_mean_grey():
    images = th.randint(60, 200, (3, 3, 5, 5), dtype=th.uint8)  # no clipping at this strength
    out = random_colour(images, 0.1, generator=th.Generator().manual_seed(4))
    matrices, contrast, brightness = colour_transforms(3, 0.1, th.Generator().manual_seed(4))
    pixels = images.float().permute(0, 2, 3, 1)  # (n, h, w, 3)
    mean = pixels.mean(dim=(1, 2, 3))
    expected = (th.einsum('nij,nhwj->nhwi', matrices, pixels)
                + (brightness * (1 - contrast) * mean)[:, None, None, None])
    assert th.allclose(out.permute(0, 2, 3, 1), expected, atol=1e-3)


def test_the_goal_stays_green_under_every_jitter_of_strength_02():
    goal = th.tensor([0.05, 0.85, 0.10]) * 255  # worlds/*.xml: goal_mat
    matrices, contrast, brightness = colour_transforms(5000, 0.2, th.Generator().manual_seed(5))
    # the goal's pixels, in images whose mean grey is anywhere from black to white
    for mean in (0.0, 128.0, 255.0):
        jittered = (matrices @ goal + (brightness * (1 - contrast) * mean)[:, None]).clamp(0, 255)
        assert all(green_excess(tuple(c / 255 for c in rgb)) > 0 for rgb in jittered.tolist())
