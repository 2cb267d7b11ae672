"""How a set's outcomes vary with its scenarios' drawn looks (pure: no ROS, no torch).

With the sim parameter ``randomize_look`` every scenario draws a look
(:mod:`nav_sim.core.looks`), and the evaluation's traces keep it (``scenario.look``).  This
counts the held-out outcomes per factor of the look that a policy might fail on:

- ``obstacle hue band``: the band of the obstacles' hue (:func:`nav_sim.core.looks.hue_band`;
  the held-out looks draw from the odd bands, the training looks from the even ones);
- ``obstacle luminance``: the obstacles' luminance (Rec. 709 weights on their 0-1 material
  colour), in fixed bins (:data:`LUMINANCE_EDGES`) so that the counts of different trials and
  sweeps add up.

Counts, not rates, so that a comparison pools trials (an exported summary's included) by adding
them: ``{factor: {bin: [episodes, successes, collisions, time-outs]}}``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from nav_sim.core.events import OUTCOMES
from nav_sim.core.looks import BANDS, HUE_SPAN, HUE_START, hue_band

HUE = 'obstacle hue band'
LUMINANCE = 'obstacle luminance'
FACTORS = (HUE, LUMINANCE)
#: the obstacle luminance's bin edges: about the quartiles of the held-out looks (201-300)
LUMINANCE_EDGES = (0.25, 0.35, 0.45)
REC709 = (0.2126, 0.7152, 0.0722)

Counts = dict[str, dict[str, list[int]]]


def luminance(rgb: Iterable[float]) -> float:
    """Return a 0-1 RGB colour's luminance (Rec. 709 weights, no gamma)."""
    return sum(w * float(c) for w, c in zip(REC709, rgb, strict=True))


def band_label(band: int) -> str:
    """Return a hue band's label: its number and its hues in degrees (``band 11 (40-60°)``)."""
    width = HUE_SPAN / BANDS
    low = (HUE_START + band * width) % 360.0
    return f'band {band:02d} ({low:.0f}–{low + width:.0f}°)'


def luminance_label(value: float) -> str:
    """Return the label of the luminance bin that ``value`` falls in."""
    edges = LUMINANCE_EDGES
    if value < edges[0]:
        return f'< {edges[0]:.2f}'
    for low, high in zip(edges, edges[1:], strict=False):
        if value < high:
            return f'{low:.2f}–{high:.2f}'
    return f'≥ {edges[-1]:.2f}'


def look_bins(look: Mapping[str, Any]) -> dict[str, str]:
    """Return, per factor, the bin of one scenario's look (a trace's ``scenario.look``)."""
    obstacles = tuple(float(c) for c in look['obstacles'])
    band = hue_band(obstacles)
    hue = band_label(band) if band is not None else \
        'grey' if max(obstacles) == min(obstacles) else 'outside the drawn hues'
    return {HUE: hue, LUMINANCE: luminance_label(luminance(obstacles))}


def count_outcomes(traces: Iterable[tuple[Any, dict[str, Any]]]) -> Counts:
    """Count the outcomes of traced episodes per factor and bin of their looks.

    ``traces`` are ``(path, trace)`` pairs, as :func:`nav_gym.training.run_dir.read_traces`
    yields them.  An episode without a drawn look (the plain look, or a trace from before looks)
    or with one that lacks the obstacles' colour counts nowhere, so a set without looks gives
    ``{}``.
    """
    counts: Counts = {}
    for _, trace in traces:
        look = (trace.get('scenario') or {}).get('look')
        try:
            bins = look_bins(look) if look else {}
        except (KeyError, TypeError, ValueError):  # a look this cannot read: counts nowhere
            continue
        outcome = trace.get('outcome')
        for factor, label in bins.items():
            row = counts.setdefault(factor, {}).setdefault(label, [0] * (1 + len(OUTCOMES)))
            row[0] += 1
            if outcome in OUTCOMES:
                row[1 + OUTCOMES.index(outcome)] += 1
    return counts


def add(counts: Iterable[Mapping[str, Mapping[str, list[int]]]]) -> Counts:
    """Return the sum of several trials' counts (the pool of a configuration)."""
    out: Counts = {}
    for one in counts:
        for factor, bins in one.items():
            for label, row in bins.items():
                total = out.setdefault(factor, {}).setdefault(label, [0] * len(row))
                for i, v in enumerate(row):
                    total[i] += int(v)
    return out


def rows(counts: Mapping[str, Mapping[str, list[int]]]) -> list[dict[str, Any]]:
    """Return one row per factor and bin: the episodes and the share of each outcome."""
    out = []
    for factor in [f for f in FACTORS if f in counts] + sorted(set(counts) - set(FACTORS)):
        for label in sorted(counts[factor], key=_bin_order):
            episodes, *outcomes = counts[factor][label]
            out.append({'factor': factor, 'bin': label, 'episodes': episodes,
                        **{f'{o}_rate': n / episodes if episodes else None
                           for o, n in zip(OUTCOMES, outcomes, strict=True)}})
    return out


def _bin_order(label: str) -> tuple[int, str]:
    """Sort bins in their natural order: bands by number, luminance from dark to bright."""
    return (0 if label.startswith('<') else 2 if label.startswith('≥') else 1, label)
