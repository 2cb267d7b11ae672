"""The learner: SB3's DQN, or Double DQN (van Hasselt et al. 2016), timed into the step budget.

The workshop's learner is SB3's ``DQN``: its TD target takes the *maximum* of the target
network's Q-values at the next observation, which overestimates where the actions' true values
are close (the max of noisy estimates is biased up, and bootstrapping carries the bias on).
Double DQN lets the online network pick the next action and the target network value it.
Everything else (network, replay, exploration, the workshop's hyperparameters, the saved model
format) is SB3's: a Double DQN checkpoint loads with ``DQN.load`` like any other.

Not the workshop's learner and never a default (``double_q: false`` in config/train.yaml): it
exists to test whether the learning target's misses come from the learner's overestimation
(docs/experiments.md).  :func:`learner_class` picks the class a run trains with.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import DQN
from torch.nn import functional as F


def double_q_target(rewards: th.Tensor, dones: th.Tensor, discounts: th.Tensor | float,
                    next_q_online: th.Tensor, next_q_target: th.Tensor) -> th.Tensor:
    """Return the Double DQN TD target, ``(batch, 1)``.

    ``next_q_online`` picks the next action (argmax), ``next_q_target`` values it; a done
    transition's target is its reward.
    """
    next_actions = next_q_online.argmax(dim=1, keepdim=True)
    next_values = th.gather(next_q_target, dim=1, index=next_actions)
    return rewards + (1 - dones) * discounts * next_values


class DoubleDQN(DQN):
    """SB3's DQN whose TD target is Double DQN's (see the module docstring)."""

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        """Run ``gradient_steps`` gradient steps, as SB3's ``DQN.train`` with the double target."""
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses = []
        for _ in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)
            discounts = (replay_data.discounts if replay_data.discounts is not None
                         else self.gamma)
            with th.no_grad():
                target_q_values = double_q_target(
                    replay_data.rewards, replay_data.dones, discounts,
                    self.q_net(replay_data.next_observations),
                    self.q_net_target(replay_data.next_observations))
            current_q_values = th.gather(self.q_net(replay_data.observations), dim=1,
                                         index=replay_data.actions.long())
            loss = F.smooth_l1_loss(current_q_values, target_q_values)
            losses.append(loss.item())
            self.policy.optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record('train/n_updates', self._n_updates, exclude='tensorboard')
        self.logger.record('train/loss', np.mean(losses))


def learner_class(timing: Any | None = None, double_q: bool = False) -> type:
    """Return a DQN class that counts its gradient steps and predictions into ``timing``.

    ``timing`` is the env's step budget (``env.timing``): SB3's ``train`` (gradient steps) and
    ``predict`` calls become the learner's share of every env step.  A subclass, not wrappers
    set on the model, so the timing never becomes model state that saving would pickle; a
    checkpoint of it loads with ``DQN.load`` as any other.  The learner is SB3's DQN, or with
    ``double_q`` :class:`DoubleDQN` (a diagnosis, not the workshop's learner); without
    ``timing`` that class itself is returned, untimed.
    """
    learner = DoubleDQN if double_q else DQN
    if timing is None:
        return learner

    class TimedDQN(learner):  # type: ignore[misc, valid-type]
        """The learner (SB3's DQN or Double DQN) with its ``train`` and ``predict`` timed."""

        def train(self, *args: Any, **kwargs: Any) -> Any:
            """Run SB3's gradient steps, timed as ``gradient_step``."""
            start = time.perf_counter()
            try:
                return super().train(*args, **kwargs)
            finally:
                timing.add('gradient_step', time.perf_counter() - start)

        def predict(self, *args: Any, **kwargs: Any) -> Any:
            """Run SB3's ``predict``, timed as ``predict``."""
            start = time.perf_counter()
            try:
                return super().predict(*args, **kwargs)
            finally:
                timing.add('predict', time.perf_counter() - start)

    return TimedDQN
