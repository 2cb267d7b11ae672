"""Periodic resets of the fully connected layers (Nikishin et al. 2022): what, when, and not."""

from __future__ import annotations

import pytest
import torch as th
from torch import nn

from helpers import learner_env
from nav_gym.training.learner import Learner, learner_class, learner_kwargs, learner_policy
from nav_gym.training.resets import reset_fully_connected
from nav_gym.training.spec import LearnerSpec


def _model(spaces_only, spec: LearnerSpec) -> Learner:
    def seeded():  # noqa: ANN202
        env = spaces_only()
        env.observation_space.seed(0)  # the same frames in every run
        return env
    return learner_class(None, spec)(learner_policy(spec), learner_env(seeded, spec),
                                     buffer_size=200,
                                     learning_starts=40, batch_size=8, train_freq=4, seed=1,
                                     device='cpu', **learner_kwargs(spec, 0.99))


def _snapshot(net: nn.Module) -> dict[str, th.Tensor]:
    return {name: value.detach().clone() for name, value in net.state_dict().items()}


@pytest.mark.parametrize('spec', [LearnerSpec(), LearnerSpec(dueling=True, aux_depth=1.0)],
                         ids=['default', 'dueling+depth'])
def test_a_reset_renews_the_fully_connected_layers_and_their_adam_state_only(spaces_only, spec):
    model = _model(spaces_only, spec)
    model.learn(80)  # trained: every parameter has Adam state
    optimizer, net = model.policy.optimizer, model.q_net
    had = set(optimizer.state)  # every parameter with a gradient (the depth head has none:
    assert had >= set(net.features_extractor.parameters())  # no depth in these envs' infos)
    before, target = _snapshot(net), _snapshot(model.q_net_target)
    linear = {id(p) for m in net.modules() if isinstance(m, nn.Linear) for p in m.parameters()}
    heads = 2 + 2 * spec.dueling + 2 * bool(spec.aux_depth)  # Q (+ value, + depth) heads
    assert reset_fully_connected(net, optimizer) == 1 + heads // 2  # and NatureCNN's hidden one
    after = _snapshot(net)
    for name, param in net.named_parameters():
        renewed = id(param) in linear
        assert (not th.equal(before[name], after[name])) == renewed, name
        assert (param in optimizer.state) == (param in had and not renewed), name
    assert sum(id(p) in linear for p in net.parameters()) == 2 + heads
    assert all(th.equal(target[k], v) for k, v in _snapshot(model.q_net_target).items())
    model.learn(40, reset_num_timesteps=False)  # Adam starts the renewed layers afresh
    assert set(optimizer.state) == had
    steps = {id(p): int(optimizer.state[p]['step']) for p in had}
    kept = steps[id(next(net.features_extractor.cnn.parameters()))]
    assert all(steps[id(p)] < kept for p in had if id(p) in linear)  # counted from the reset


def test_resets_come_every_interval_once_learning_has_begun(spaces_only, monkeypatch):
    from nav_gym.training import learner
    calls = []
    monkeypatch.setattr(learner, 'reset_fully_connected',
                        lambda net, optimizer: calls.append(0) or 0)
    model = _model(spaces_only, LearnerSpec(reset_interval=25))
    model.learn(150)
    # at 50, 75, 100 and 125; not at 25 (still collecting), nor where fewer than 25 steps of
    # training would follow (150: the final model would be an untrained head)
    assert model.resets == len(calls) == 4
    never = _model(spaces_only, LearnerSpec(reset_interval=0))
    never.learn(150)
    assert never.resets == 0 and len(calls) == 4


def test_resets_not_due_keep_the_learner_bit_for_bit_and_a_checkpoint_loads(spaces_only, tmp_path):
    from nav_gym.training.learner import load_checkpoint
    runs = {}
    for spec in (LearnerSpec(reset_interval=0), LearnerSpec(reset_interval=1000)):  # none due
        model = _model(spaces_only, spec)
        model.learn(80)
        runs[spec.reset_interval] = _snapshot(model.q_net)
    assert all(th.equal(runs[0][k], runs[1000][k]) for k in runs[0])
    spec = LearnerSpec(reset_interval=30)
    model = _model(spaces_only, spec)
    model.learn(100)
    model.save(tmp_path / 'model.zip')
    loaded = load_checkpoint(tmp_path / 'model.zip', spec, device='cpu')
    assert loaded.learner == spec and loaded.resets == model.resets == 1  # at 60 (not 90)
