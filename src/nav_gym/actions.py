"""The discrete actions of the env: the one definition of their names and short labels."""

from __future__ import annotations

#: action index -> name: 0 turn left, 1 forward, 2 turn right (``Discrete(3)``)
ACTION_NAMES = ('left', 'forward', 'right')
#: short labels of the actions for figures and frame captions, by action index
ACTION_LABELS = ('left', 'fwd', 'right')


def action_label(name: str) -> str:
    """Return the short label of an action name (an unknown name unchanged)."""
    return ACTION_LABELS[ACTION_NAMES.index(name)] if name in ACTION_NAMES else name
