"""The discrete actions of the env: the one definition of their names, labels and twists."""

from __future__ import annotations

from typing import Any

#: action index -> name: 0 turn left, 1 forward, 2 turn right (``Discrete(3)``)
ACTION_NAMES = ('left', 'forward', 'right')
#: short labels of the actions for figures and frame captions, by action index
ACTION_LABELS = ('left', 'fwd', 'right')


def action_label(name: str) -> str:
    """Return the short label of an action name (an unknown name unchanged)."""
    return ACTION_LABELS[ACTION_NAMES.index(name)] if name in ACTION_NAMES else name


def action_twists(config: Any) -> tuple[tuple[float, float], ...]:
    """Return each action's commanded ``cmd_vel`` (linear m/s, angular rad/s), by action index.

    ``config`` has the env's action settings (an ``EnvConfig``): left and right arc at
    ``turn_speed`` with ``+-turn_rate``, forward drives straight at ``forward_speed``.
    """
    return ((config.turn_speed, config.turn_rate), (config.forward_speed, 0.0),
            (config.turn_speed, -config.turn_rate))
