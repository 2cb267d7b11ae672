"""Files saved before the house move still load and resume (SB3 pickles classes by path).

``data/dqn_32_steps.zip`` and ``data/replay_buffer.pkl`` were written by the code of commit
e6356e5, before nav_gym's modules moved into sub-packages: a learner with a dueling head,
prioritized replay and 3-step returns (a small feature layer keeps the files small), 32 steps
on random frames.  The checkpoint pickles ``nav_gym.learner.DuelingCnnPolicy`` and
``nav_gym.train_config.LearnerSpec``; the buffer is a ``nav_gym.learner.PrioritizedReplayBuffer``.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from nav_gym.training.learner import (
    DuelingCnnPolicy,
    Learner,
    PrioritizedReplayBuffer,
    load_checkpoint,
)
from nav_gym.training.spec import LearnerSpec

DATA = Path(__file__).parent / 'data'


class Frames(gym.Env):
    """Random camera-sized frames: the saved model's spaces, without a sim."""

    observation_space = gym.spaces.Box(0, 255, (3, 84, 84), np.uint8)
    action_space = gym.spaces.Discrete(3)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self.observation_space.sample(), {}

    def step(self, action):
        self.t += 1
        return self.observation_space.sample(), float(action == 1), self.t >= 7, False, {}


def test_a_checkpoint_and_replay_buffer_saved_before_the_move_resume():
    # the learner it trained: the default of its time had no memory and no resets
    spec = LearnerSpec(dueling=True, prioritized_replay=True, n_steps=3, frame_stack=1,
                       previous_action=False, reset_interval=0)
    model = load_checkpoint(DATA / 'dqn_32_steps.zip', spec, env=Frames(), device='cpu')
    assert isinstance(model, Learner) and isinstance(model.policy, DuelingCnnPolicy)
    assert model.num_timesteps == 32 and model.learner == spec
    model.load_replay_buffer(DATA / 'replay_buffer.pkl')
    buffer = model.replay_buffer
    assert isinstance(buffer, PrioritizedReplayBuffer) and buffer.size() == 32
    assert buffer.observations.dtype == np.uint8 and buffer.observations.any()
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(16, reset_num_timesteps=False)  # resumes: collects, samples, updates
    assert model.num_timesteps == 48 and buffer.size() == 48
    assert any(not (a == b.detach()).all() for a, b in zip(before, model.policy.parameters(),
                                                             strict=True))


def test_a_checkpoint_from_before_the_memory_defaults_acts_on_one_frame():
    from nav_gym.policy.actors import DQNActor
    from nav_gym.training.spec import LEGACY_DEFAULTS

    # its pickled spec names no frame_stack, previous_action or reset_interval: unpickled as
    # today's defaults, the actor wanted a 4-frame stack with action planes of 3 channels
    actor = DQNActor(DATA / 'dqn_32_steps.zip')
    saved = actor.model.learner
    assert (saved.frame_stack, saved.previous_action, saved.reset_interval) == (
        LEGACY_DEFAULTS['frame_stack'], LEGACY_DEFAULTS['previous_action'],
        LEGACY_DEFAULTS['reset_interval']) == (1, False, 0)
    assert (saved.dueling, saved.prioritized_replay, saved.n_steps) == (True, True, 3)  # as saved
    actor.begin_episode(1)
    action, q_values = actor.act(np.zeros((3, 84, 84), np.uint8))
    assert action in (0, 1, 2) and len(q_values) == 3
