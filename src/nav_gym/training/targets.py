"""The TD targets the learner's flags choose between (no SB3, tensors in and out).

DQN's (SB3's own: the target network's best next value), Double DQN's (van Hasselt et al. 2016:
the online network picks, the target network values) and Munchausen DQN's (Vieillard et al.
2020).  Each is ``(batch, 1)`` from SB3's replay samples: ``rewards`` (n-step returns where the
buffer makes them), ``dones`` and ``discounts`` (``gamma ** n``, fewer steps at an episode's
end).
"""

from __future__ import annotations

import torch as th
from torch.nn import functional as F

#: Munchausen DQN's constants, the paper's (Vieillard et al. 2020, for Atari): the softmax
#: temperature, the log-policy's scale and its lower clip
MUNCHAUSEN_TAU, MUNCHAUSEN_ALPHA, MUNCHAUSEN_CLIP = 0.03, 0.9, -1.0



def double_q_target(rewards: th.Tensor, dones: th.Tensor, discounts: th.Tensor | float,
                    next_q_online: th.Tensor, next_q_target: th.Tensor) -> th.Tensor:
    """Return the Double DQN TD target, ``(batch, 1)``.

    ``next_q_online`` picks the next action (argmax), ``next_q_target`` values it; a done
    transition's target is its reward.
    """
    next_actions = next_q_online.argmax(dim=1, keepdim=True)
    next_values = th.gather(next_q_target, dim=1, index=next_actions)
    return rewards + (1 - dones) * discounts * next_values


def max_q_target(rewards: th.Tensor, dones: th.Tensor, discounts: th.Tensor | float,
                 next_q_target: th.Tensor) -> th.Tensor:
    """Return DQN's TD target, ``(batch, 1)``: the target network's best next value."""
    next_values = next_q_target.max(dim=1).values.reshape(-1, 1)
    return rewards + (1 - dones) * discounts * next_values


def munchausen_target(rewards: th.Tensor, dones: th.Tensor, discounts: th.Tensor | float,
                      q_target: th.Tensor, actions: th.Tensor, next_q_target: th.Tensor,
                      tau: float = MUNCHAUSEN_TAU, alpha: float = MUNCHAUSEN_ALPHA,
                      clip: float = MUNCHAUSEN_CLIP) -> th.Tensor:
    """Return the Munchausen DQN target, ``(batch, 1)`` (Vieillard et al. 2020, eq. 2).

    ``q_target`` and ``next_q_target``: the target network's values of the observation and of
    the next one; ``pi = softmax(q / tau)``.  The target is the reward, plus ``alpha`` times
    ``tau log pi`` of the action taken clipped to ``[clip, 0]`` (as the paper's and its
    reference code's ``l0``), plus the discounted soft
    value ``sum_a' pi(a') (q(a') - tau log pi(a'))`` of the next observation (none when done).
    With n-step returns the reward is SB3's n-step return and the bonus is the first action's:
    the bonuses and entropies of the steps between are left out.
    """
    log_pi = F.log_softmax(q_target / tau, dim=1)
    bonus = alpha * (tau * th.gather(log_pi, 1, actions.long())).clamp(clip, 0.0)
    next_log_pi = F.log_softmax(next_q_target / tau, dim=1)
    soft_value = (next_log_pi.exp() * (next_q_target - tau * next_log_pi)).sum(1, keepdim=True)
    return rewards + bonus + (1 - dones) * discounts * soft_value
