"""Image augmentations of sampled observations (the learner's; the env's images are untouched).

- :func:`random_shift`: DrQ's random shifts (``augment_shift``);
- :func:`random_colour`: colour jitter (``augment_colour``): brightness, contrast, saturation
  and hue, as RAD's (Laskin et al. 2020), drawn per observation and shared by the frames of one
  stack.  Every part is linear in the pixel, so each observation gets one 3 x 3 matrix and one
  offset: saturation and hue act about the grey axis (hue turns about it, saturation scales the
  distance from it), and both keep an image's mean grey, which contrast scales the pixels about.

Both draw from torch's global generator unless given one, and draw nothing when off, so a
learner without them trains bit for bit as before.
"""

from __future__ import annotations

import math

import torch as th

#: the hue turns by up to ``strength`` x this many degrees: strength 0.2 turns it by up to one
#: band of the looks' palettes (20 degrees, ``nav_sim.core.looks.BANDS`` over 240 degrees)
HUE_DEGREES = 100.0


def random_shift(images: th.Tensor, pad: int, generator: th.Generator | None = None,
                 ) -> th.Tensor:
    """Shift each image of ``(N, C, H, W)`` by its own random offset of up to ``pad`` pixels.

    The same as DrQ's augmentation: pad every side by ``pad`` pixels, replicating the edge,
    then crop an ``H x W`` window at a random position (independent per image, uniform over
    the ``(2 pad + 1)^2`` positions).  Done as one gather with clamped indices, on any dtype
    (uint8 here, before SB3 scales the image); ``pad`` 0 returns the images unchanged.
    """
    if pad < 0:
        raise ValueError(f'pad must be >= 0, got {pad}')
    n, c, h, w = images.shape
    if pad == 0 or n == 0:
        return images
    device = images.device
    dy = th.randint(-pad, pad + 1, (n, 1), generator=generator, device=device)
    dx = th.randint(-pad, pad + 1, (n, 1), generator=generator, device=device)
    rows = (th.arange(h, device=device) + dy).clamp_(0, h - 1)
    cols = (th.arange(w, device=device) + dx).clamp_(0, w - 1)
    index = (rows[:, :, None] * w + cols[:, None, :]).reshape(n, 1, h * w).expand(n, c, h * w)
    return images.reshape(n, c, h * w).gather(2, index).reshape(n, c, h, w)


def colour_transforms(n: int, strength: float, generator: th.Generator | None = None,
                      device: th.device | str = 'cpu',
                      ) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
    """Draw ``n`` colour jitters: ``(matrices (n, 3, 3), contrasts (n,), brightnesses (n,))``.

    Brightness, contrast and saturation are factors from ``[1 - strength, 1 + strength]``, the
    hue angle is from ``+-strength * HUE_DEGREES``.  The matrix is brightness x contrast x
    saturation x the hue's rotation (Rodrigues' formula about the unit grey axis).
    """
    def uniform(half_width: float) -> th.Tensor:
        return half_width * (2 * th.rand(n, generator=generator, device=device) - 1)

    brightness, contrast, saturation = (1 + uniform(strength) for _ in range(3))
    angle = uniform(math.radians(strength * HUE_DEGREES))
    eye = th.eye(3, device=device)
    grey = th.full((3, 3), 1 / 3, device=device)  # the projection on the grey axis
    u = 1 / math.sqrt(3)
    cross = th.tensor([[0, -u, u], [u, 0, -u], [-u, u, 0]], device=device)  # k x, k the axis
    rotation = (eye + angle.sin()[:, None, None] * cross
                + (1 - angle.cos())[:, None, None] * (grey - eye))
    saturated = saturation[:, None, None] * rotation + (1 - saturation)[:, None, None] * grey
    return (brightness * contrast)[:, None, None] * saturated, contrast, brightness


def random_colour(images: th.Tensor, strength: float, frames: int = 1,
                  generator: th.Generator | None = None) -> th.Tensor:
    """Jitter the colours of each observation of ``(N, C, H, W)``, 0-255 valued; see the module.

    The first ``3 * frames`` channels are ``frames`` RGB frames, which share their
    observation's jitter; the channels after them (the previous action's planes) are left as
    they are.  Returns float images clipped to 0-255 (SB3 scales them as it does uint8 ones);
    ``strength`` 0 returns the images unchanged.
    """
    if not 0 <= strength < 1:
        raise ValueError(f'strength must be in [0, 1), got {strength}')
    n, c, h, w = images.shape
    if strength == 0 or n == 0:
        return images
    if not 1 <= frames <= c // 3:
        raise ValueError(f'{frames} RGB frames do not fit {c} channels')
    matrices, contrast, brightness = colour_transforms(n, strength, generator, images.device)
    colour = images[:, :3 * frames].reshape(n, frames, 3, h * w).float()
    offset = brightness * (1 - contrast) * colour.mean(dim=(1, 2, 3))  # around the mean grey
    jittered = th.matmul(matrices[:, None], colour).add_(offset[:, None, None, None])
    jittered = jittered.clamp_(0, 255).reshape(n, 3 * frames, h, w)
    if c == 3 * frames:
        return jittered
    return th.cat([jittered, images[:, 3 * frames:].float()], dim=1)
