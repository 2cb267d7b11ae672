"""The image-only visual servo: turn toward the green goal pixels, drive when they are centred.

Pure (numpy only).  The one definition of the servo's logic, shared by the evaluation's
baseline (:class:`nav_eval.evaluation.policies.ServoPolicy`), the failure-layer checks of the
diagnosis (:mod:`nav_eval.analysis.failure_layers`) and the policy node's ``policy:=servo``
(:mod:`nav_gym.policy`).  It needs no learning: it asks whether a scenario is solvable from
single images.
"""

from __future__ import annotations

import math

import numpy as np

#: what the servo does while the goal is not in view: turn left (action 0)
SEARCH_ACTION = 0


def goal_mask(obs: np.ndarray) -> np.ndarray:
    """Pixels of the green goal marker in a (3, H, W) observation."""
    r, g, b = (obs[i].astype(np.int16) for i in range(3))
    return (g > 120) & (g - r > 60) & (g - b > 60)


def goal_bearing(obs: np.ndarray, min_pixels: int = 2) -> float | None:
    """Horizontal position of the goal in the image, -1 (left edge) .. +1 (right edge)."""
    mask = goal_mask(obs)
    if int(mask.sum()) < min_pixels:
        return None
    columns = np.nonzero(mask)[1]
    return float(columns.mean() / (obs.shape[2] - 1) * 2.0 - 1.0)


def centre_band(turn_step: float, hfov: float) -> float:
    """Return the half-width of 'centred' in bearing units: a bit over half a turn step.

    A turn cannot centre the goal better than that.
    """
    return min(0.9, 1.2 * turn_step / hfov)


def servo_band(turn_rate: float, control_period: float, hfov_deg: float) -> float:
    """Return the 'centred' band that fits one turn step of these actions and this camera."""
    return centre_band(turn_rate * control_period, math.radians(hfov_deg))


def servo_action(bearing: float | None, band: float = 0.3) -> int | None:
    """Return what a visual servo would do: turn toward a visible goal, drive when centred.

    Centred means ``|bearing| <= band``; None when the goal is not in view.
    """
    if bearing is None:
        return None
    return 0 if bearing < -band else (2 if bearing > band else 1)


def servo_act(observation: np.ndarray, band: float) -> int:
    """Return the servo's action for one observation: steer to the goal, else search (left)."""
    action = servo_action(goal_bearing(observation), band)
    return SEARCH_ACTION if action is None else action
