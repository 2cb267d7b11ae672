"""Double DQN's target and its use by training (a diagnosis learner, off by default)."""

from __future__ import annotations

import pytest
import torch as th

from nav_gym.learner import DoubleDQN, double_q_target, learner_class
from nav_gym.train_config import TrainConfig


def test_the_online_network_picks_and_the_target_network_values():
    online = th.tensor([[1.0, 3.0, 2.0], [5.0, 0.0, 0.0]])
    target = th.tensor([[9.0, 4.0, 7.0], [2.0, 8.0, 8.0]])
    rewards = th.tensor([[0.5], [1.0]])
    dones = th.tensor([[0.0], [1.0]])
    out = double_q_target(rewards, dones, 0.9, online, target)
    # row 0: online argmax is action 1, valued 4 by the target network (DQN would take 9)
    assert out.flatten().tolist() == pytest.approx([0.5 + 0.9 * 4.0, 1.0])


def test_it_is_off_by_default_and_chosen_by_the_config():
    assert TrainConfig().double_q is False
    assert 'double_q' not in TrainConfig().dqn_kwargs()  # not an SB3 argument
    assert issubclass(learner_class(None, double_q=True), DoubleDQN)
    assert not issubclass(learner_class(None), DoubleDQN)
    assert issubclass(learner_class(object(), double_q=True), DoubleDQN)  # timed, too
