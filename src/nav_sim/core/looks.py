"""Seeded looks: the colours of floor, walls and obstacles and the light, drawn per scenario.

With the sim parameter ``randomize_look`` (off by default) every reset draws a :class:`Look`
from its scenario's seed and split, and ``nav_sim.core.world.World.apply_look`` puts it on the
model.  The invariants (docs/worlds.md):

- **Seeded, apart from the scenario.**  A look is drawn from
  ``numpy.random.default_rng([split_id, seed, LOOK_STREAM])``, never from the scenario's own
  generator: layouts, starts and goals are those of the plain world, and one (seed, split)
  always gives the same look, so the same bytes in every image.
- **The goal's hue is reserved.**  A colour takes the goal's hue when green is its greatest
  channel (hue strictly between 60 and 180 degrees: :func:`green_excess` > 0), which is what
  the goal detector looks for (``nav_gym.policy.servo.goal_mask``: green above red
  and blue).  Drawn hues lie outside that range (180 to 420 degrees: cyan, blue, magenta, red,
  orange, yellow) and the light stays white, so no drawn surface takes it; the goal's own
  material is never changed.
- **Disjoint palettes.**  The drawn hues are cut into ``BANDS`` bands of equal width; a
  training look takes its colours from the even bands, a held-out look from the odd ones
  (with ``BAND_MARGIN`` left free at each edge), so a held-out look never shows a surface
  colour a training look can have.  The light (direction and intensity) is drawn from the same
  range for both splits.
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from nav_sim.core.scenarios import SPLIT_IDS

LOOK_STREAM = 7_004  # the look's own stream of a scenario's seed (any constant but 0)
HUE_START, HUE_SPAN = 180.0, 240.0  # degrees: the drawn hues, clear of the goal's 60-180
BANDS = 12                          # bands of 20 degrees: even for training, odd for held-out
BAND_MARGIN = 1.0                   # degrees left free at each edge of a band
#: per surface: the (saturation, value) ranges its colour is drawn from
SURFACES = {
    'floor': ((0.1, 0.6), (0.55, 1.0)),  # the floor's material tints its grey checker texture
    'walls': ((0.1, 0.6), (0.55, 0.95)),
    'obstacles': ((0.5, 0.9), (0.45, 0.9)),
}
LIGHT_ELEVATION = (35.0, 90.0)  # degrees above the horizon the light comes from
LIGHT_DIFFUSE = (0.3, 0.7)      # the lights' diffuse intensity (white)
AMBIENT = (0.3, 0.55)           # the headlight's ambient intensity (white)

Colour = tuple[float, float, float]


@dataclass(frozen=True)
class Look:
    """One drawn look: surface colours (RGB, 0-1), the lights' direction and intensity."""

    floor: Colour
    walls: Colour
    obstacles: Colour
    light_dir: tuple[float, float, float]  # the direction the light shines (unit, downward)
    light_diffuse: float
    ambient: float

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready description (rounded; the scenario description carries it)."""
        def rounded(values: tuple[float, ...]) -> list[float]:
            return [round(v, 4) for v in values]
        return {'floor': rounded(self.floor), 'walls': rounded(self.walls),
                'obstacles': rounded(self.obstacles), 'light_dir': rounded(self.light_dir),
                'light_diffuse': round(self.light_diffuse, 4), 'ambient': round(self.ambient, 4)}


def bands_of(split: str) -> tuple[int, ...]:
    """Return the hue bands a split's looks draw from (training even, held-out odd)."""
    return tuple(range(SPLIT_IDS[split] % 2, BANDS, 2))


def hue_band(rgb: Colour) -> int | None:
    """Return the band of a colour's hue (None for a grey or a hue outside the drawn range)."""
    hue, saturation, _ = colorsys.rgb_to_hsv(*rgb)
    if saturation == 0.0:
        return None
    offset = (hue * 360.0 - HUE_START) % 360.0
    return int(offset // (HUE_SPAN / BANDS)) if offset < HUE_SPAN else None


def green_excess(rgb: Colour | np.ndarray) -> float:
    """Return how far green exceeds the larger of red and blue (> 0: the goal's hues)."""
    r, g, b = (float(v) for v in rgb[:3])
    return g - max(r, b)


def draw_colour(rng: np.random.Generator, bands: tuple[int, ...],
                saturation: tuple[float, float], value: tuple[float, float]) -> Colour:
    """Draw a colour whose hue lies in one of ``bands`` (away from their edges)."""
    width = HUE_SPAN / BANDS
    band = int(bands[int(rng.integers(len(bands)))])
    hue = HUE_START + band * width + rng.uniform(BAND_MARGIN, width - BAND_MARGIN)
    r, g, b = colorsys.hsv_to_rgb((hue % 360.0) / 360.0, rng.uniform(*saturation),
                                  rng.uniform(*value))
    return float(r), float(g), float(b)


def draw_look(seed: int, split: str) -> Look:
    """Draw the look of scenario (seed, split): the same look for the same seed and split."""
    rng = np.random.default_rng([SPLIT_IDS[split], seed, LOOK_STREAM])
    bands = bands_of(split)
    colours = {name: draw_colour(rng, bands, *ranges) for name, ranges in SURFACES.items()}
    elevation = math.radians(rng.uniform(*LIGHT_ELEVATION))
    azimuth = rng.uniform(-math.pi, math.pi)
    direction = (math.cos(elevation) * math.cos(azimuth),
                 math.cos(elevation) * math.sin(azimuth), -math.sin(elevation))
    return Look(colours['floor'], colours['walls'], colours['obstacles'], direction,
                float(rng.uniform(*LIGHT_DIFFUSE)), float(rng.uniform(*AMBIENT)))
