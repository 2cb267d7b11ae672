"""The learner: Double DQN targets by default, and each component on constructed tensors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.buffers import NStepReplayBuffer

from helpers import learner_env
from nav_gym.training.config import TrainConfig
from nav_gym.training.learner import (
    DuelingCnnPolicy,
    DuelingQNetwork,
    Learner,
    PrioritizedReplayBuffer,
    SumTree,
    dueling_q,
    learner_class,
    learner_kwargs,
    learner_policy,
    load_checkpoint,
)
from nav_gym.training.spec import COMPONENTS, WITHOUT_MEMORY, LearnerSpec
from nav_gym.training.targets import double_q_target, max_q_target, munchausen_target
from nav_sim.core.depth import DEPTH_SHAPE

OBS = spaces.Box(0, 255, (3, 84, 84), np.uint8)
ACTIONS = spaces.Discrete(3)


def test_the_online_network_picks_and_the_target_network_values():
    online = th.tensor([[1.0, 3.0, 2.0], [5.0, 0.0, 0.0]])
    target = th.tensor([[9.0, 4.0, 7.0], [2.0, 8.0, 8.0]])
    rewards = th.tensor([[0.5], [1.0]])
    dones = th.tensor([[0.0], [1.0]])
    out = double_q_target(rewards, dones, 0.9, online, target)
    # row 0: online argmax is action 1, valued 4 by the target network (DQN would take 9)
    assert out.flatten().tolist() == pytest.approx([0.5 + 0.9 * 4.0, 1.0])
    assert max_q_target(rewards, dones, 0.9, target).flatten().tolist() == pytest.approx(
        [0.5 + 0.9 * 9.0, 1.0])


def test_the_munchausen_target_adds_the_clipped_log_policy_and_a_soft_value():
    tau, alpha = 0.03, 0.9

    def tau_log_pi(q: list[float]) -> np.ndarray:  # tau log softmax(q / tau), by hand
        z = np.array(q) / tau
        return tau * (z - z.max() - np.log(np.exp(z - z.max()).sum()))

    # row 0: the action taken (1) is 0.1 below the best: tau log pi = -0.1 (and a little),
    # inside the clip; row 1: action 2 is 2 below the best: tau log pi = -2, clipped to -1
    q_obs = th.tensor([[1.0, 0.9, 0.5], [3.0, 3.0, 1.0]])
    next_q = th.tensor([[2.0, 1.0, 1.97], [5.0, 5.0, 5.0]])
    rewards, dones = th.tensor([[0.5], [1.0]]), th.tensor([[0.0], [1.0]])
    actions = th.tensor([[1], [2]])
    out = munchausen_target(rewards, dones, 0.9, q_obs, actions, next_q, tau, alpha, -1.0)
    bonus = alpha * np.clip(tau_log_pi([1.0, 0.9, 0.5])[1], -1.0, 0.0)
    assert -0.1 * alpha > bonus > -0.11 * alpha  # how much worse the action is, not a constant
    pi_next = np.exp(tau_log_pi([2.0, 1.0, 1.97]) / tau)
    soft = float((pi_next * (np.array([2.0, 1.0, 1.97]) - tau_log_pi([2.0, 1.0, 1.97]))).sum())
    assert out[0, 0].item() == pytest.approx(0.5 + bonus + 0.9 * soft, rel=1e-5)
    assert 1.97 < soft < 2.0 + tau * np.log(3)  # between the max and max + tau ln 3
    assert out[1, 0].item() == pytest.approx(1.0 - alpha * 1.0, rel=1e-5)  # done, clipped
    # alpha 0 and a tiny temperature: DQN's own target
    assert th.allclose(munchausen_target(rewards, dones, 0.9, q_obs, actions, next_q, 1e-4, 0.0),
                       max_q_target(rewards, dones, 0.9, next_q), atol=1e-3)


def test_the_adopted_learner_is_the_default_and_sb3_dqn_is_one_file_away():
    config = TrainConfig()  # Double DQN, 3-step returns, L5's memory, replay ratio and resets
    assert (config.double_q, config.n_steps, config.frame_stack, config.previous_action,
            config.gradient_steps, config.reset_interval) == (True, 3, 4, True, 2, 20_000)
    assert TrainConfig().learner() == LearnerSpec()
    assert learner_class(None, LearnerSpec()) is Learner
    vanilla = TrainConfig(double_q=False, **COMPONENTS).learner()  # config/workshop.yaml
    assert vanilla.vanilla and learner_class(None, vanilla) is DQN  # SB3's own, untouched
    assert learner_kwargs(vanilla, 0.99) == {} and learner_policy(vanilla) == 'CnnPolicy'
    assert issubclass(learner_class(object(), LearnerSpec()), Learner)  # timed, too
    assert not TrainConfig(double_q=False, **{**COMPONENTS, 'n_steps': 3}).learner().vanilla
    assert 'double_q' not in TrainConfig().dqn_kwargs()  # not an SB3 argument


def test_every_component_has_a_flag_and_a_value_that_turns_it_off():
    spec = LearnerSpec()
    assert (spec.n_steps, spec.dueling, spec.augment_shift, spec.prioritized_replay) == (
        3, False, 0, False)  # n-step returns adopted (docs/experiments.md), the others off
    assert spec.describe() == (
        'DQN (SB3) with Double DQN targets (van Hasselt et al. 2016), 3-step returns, a 4-frame '
        'stack (Hausknecht & Stone 2015), the previous action as input (Mirowski et al. 2017), '
        'resets of the fully connected layers every 20000 steps (Nikishin et al. 2022)')
    off = LearnerSpec(**COMPONENTS)
    assert off.describe() == 'DQN (SB3) with Double DQN targets (van Hasselt et al. 2016)'
    assert dataclasses.replace(off, double_q=False).vanilla
    full = LearnerSpec(n_steps=3, dueling=True, augment_shift=4, prioritized_replay=True,
                       **WITHOUT_MEMORY)
    for part in ('Double DQN', '3-step returns', 'dueling head', 'up to 4 px', 'prioritized'):
        assert part in full.describe()
    for name in ('n_steps', 'dueling', 'augment_shift', 'prioritized_replay', 'priority_alpha',
                 'priority_beta', 'aux_depth', 'munchausen'):
        assert name in {f.name for f in dataclasses.fields(TrainConfig)}


@pytest.mark.parametrize('bad', [{'n_steps': 0}, {'augment_shift': -1}, {'priority_alpha': 1.5},
                                 {'priority_beta': -0.1}, {'munchausen': True}])
def test_a_bad_learner_setting_is_a_clear_error(bad):
    from nav_gym.errors import TrainConfigError
    with pytest.raises(TrainConfigError, match=next(iter(bad))):
        TrainConfig(**bad)


# --- n-step returns: SB3's buffer, as this learner samples it ----------------------------------
def _buffer(cls=NStepReplayBuffer, **kwargs) -> NStepReplayBuffer:
    return cls(16, spaces.Box(-1, 1, (1,), np.float32), ACTIONS, device='cpu', n_steps=3,
               gamma=0.5, **kwargs)


def _add(buffer, rewards: list[float], ends: dict[int, str]) -> None:
    """Add transitions t = 0.. with observation t; ``ends``: t -> 'goal' or 'timeout'."""
    for t, reward in enumerate(rewards):
        event = ends.get(t)
        info = {'TimeLimit.truncated': event == 'timeout'}
        buffer.add(np.array([[t]], np.float32), np.array([[t + 1]], np.float32),
                   np.array([[1]]), np.array([reward]), np.array([event is not None]), [info])


def test_n_step_targets_stop_at_an_episode_end_and_bootstrap_after_a_time_out():
    buffer = _buffer()
    # episode A: t0, t1 end in a goal at t1; episode B: t2..t5 truncated at t5; t6..t8 go on
    _add(buffer, [1.0, 2.0, 1.0, 1.0, 1.0, 4.0, 1.0, 1.0, 1.0, 1.0], {1: 'goal', 5: 'timeout'})
    data = buffer._get_samples(np.array([0, 1, 3, 4, 6]))
    returns = data.rewards.flatten().tolist()
    discounts = data.discounts.flatten().tolist()
    done = data.dones.flatten().tolist()
    nexts = data.next_observations.flatten().tolist()
    # t0: 1 + 0.5 * 2, then the goal ends it: no bootstrap
    assert (returns[0], done[0], nexts[0]) == (pytest.approx(2.0), 1.0, 2.0)
    assert (returns[1], done[1]) == (pytest.approx(2.0), 1.0)
    # t3: 1 + 0.5 * 1 + 0.25 * 4, truncated at t5: bootstrap from t5's next observation
    assert (returns[2], discounts[2], done[2], nexts[2]) == (pytest.approx(2.5), 0.125, 0.0, 6.0)
    assert (returns[3], discounts[3], done[3]) == (pytest.approx(3.0), 0.25, 0.0)
    # t6: three steps inside an episode, bootstrapped with gamma ** 3
    assert (returns[4], discounts[4], done[4], nexts[4]) == (pytest.approx(1.75), 0.125, 0.0, 9.0)


# --- the dueling head ---------------------------------------------------------------------------
def test_the_dueling_aggregation_centres_the_advantages():
    values = th.tensor([[2.0], [-1.0]])
    advantages = th.tensor([[1.0, 2.0, 3.0], [0.0, 0.0, 6.0]])
    q = dueling_q(values, advantages)
    assert q.tolist() == [[1.0, 2.0, 3.0], [-3.0, -3.0, 3.0]]
    assert (q.mean(dim=1, keepdim=True) == values).all()  # V is the mean of the Q-values
    assert (q.argmax(dim=1) == advantages.argmax(dim=1)).all()  # A alone picks the action


def test_the_dueling_policy_combines_its_two_streams(spaces_only):
    model = DQN(DuelingCnnPolicy, spaces_only(), buffer_size=64, device='cpu', seed=0)
    network = model.q_net
    assert isinstance(network, DuelingQNetwork) and isinstance(model.q_net_target,
                                                               DuelingQNetwork)
    obs = th.as_tensor(np.stack([OBS.sample(), OBS.sample()]))
    features = network.extract_features(obs, network.features_extractor)
    expected = dueling_q(network.value_net(features), network.q_net(features))
    assert th.allclose(network(obs), expected)


# --- prioritized replay -------------------------------------------------------------------------
def test_the_sum_tree_sums_and_finds_proportionally():
    tree = SumTree(5)
    tree.set(np.array([0, 1, 2, 3, 4]), np.array([1.0, 0.0, 3.0, 2.0, 4.0]))
    assert tree.total == 10.0
    # cumulative intervals: [0,1) -> 0, [1,4) -> 2 (1 has none), [4,6) -> 3, [6,10) -> 4
    assert tree.find(np.array([0.5, 1.0, 3.9, 4.0, 9.99])).tolist() == [0, 2, 2, 3, 4]
    tree.set(np.array([2]), np.array([0.5]))
    assert tree.total == 7.5 and tree.get(np.array([2])).tolist() == [0.5]


def test_priorities_follow_td_errors_and_weights_correct_the_sampling():
    buffer = _buffer(PrioritizedReplayBuffer, alpha=0.5, beta=1.0)
    _add(buffer, [0.0] * 4, {})
    assert buffer.priorities.get(np.arange(4)).tolist() == [1.0] * 4  # max priority at first
    buffer.update_priorities(np.array([0, 1, 2, 3]), np.array([3.0, -8.0, 0.0, 0.0]))
    expected = (np.array([3.0, 8.0, 0.0, 0.0]) + 1e-6) ** 0.5
    np.testing.assert_allclose(buffer.priorities.get(np.arange(4)), expected)
    np.random.seed(0)
    counts = np.zeros(4)
    for _ in range(400):
        buffer.sample(4)
        counts += np.bincount(buffer.last_indices, minlength=4)
        probabilities = expected[buffer.last_indices] / expected.sum()
        weights = (4 * probabilities) ** -1.0
        np.testing.assert_allclose(buffer.last_weights, weights / weights.max(), rtol=1e-5)
    # a zero TD error keeps only eps: about 0.02 % of the draws (0.4 of 1,600 expected)
    assert counts[2] + counts[3] <= 3
    assert counts[1] / counts[0] == pytest.approx(np.sqrt(8 / 3), rel=0.15)
    _add(buffer, [0.0], {})
    assert buffer.priorities.get(np.array([4])).tolist() == [pytest.approx(np.sqrt(8.0), 1e-5)]


# --- the learner trains, saves and loads --------------------------------------------------------
@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')  # SB3's own, on any n-step load
@pytest.mark.parametrize('spec', [LearnerSpec(), LearnerSpec(augment_shift=4, n_steps=3),
                                  LearnerSpec(dueling=True, prioritized_replay=True,
                                              **WITHOUT_MEMORY),
                                  LearnerSpec(double_q=False, munchausen=True),
                                  LearnerSpec(augment_colour=0.2),
                                  LearnerSpec(prioritized_replay=True)],
                         ids=['default', 'shift+nstep', 'dueling+per', 'munchausen', 'colour',
                              'per+memory'])
def test_a_checkpoint_of_the_learner_loads_with_dqn_load(tmp_path, spaces_only, spec):
    env = learner_env(spaces_only, spec)
    model = learner_class(None, spec)(learner_policy(spec), env, buffer_size=200,
                                      learning_starts=40, batch_size=8, train_freq=4, seed=1,
                                      device='cpu', **learner_kwargs(spec, 0.99))
    model.learn(120)
    assert model._n_updates > 0
    model.save(tmp_path / 'model.zip')
    loaded = DQN.load(tmp_path / 'model.zip', device='cpu')
    obs = env.reset()[0]  # a VecEnv's first: the default learner's stack
    assert loaded.predict(obs, deterministic=True)[0] == model.predict(obs, deterministic=True)[0]
    resumed = load_checkpoint(tmp_path / 'model.zip', spec, device='cpu')
    assert isinstance(resumed, Learner) and resumed.learner == spec
    assert model.policy.optimizer.defaults['fused'] is True


@pytest.mark.parametrize('n_envs', [1, 2])
def test_a_run_and_its_resume_end_at_their_budget_not_at_a_whole_rollout(spaces_only, n_envs):
    from stable_baselines3.common.vec_env import DummyVecEnv

    def model(cls: type) -> DQN:
        return cls('CnnPolicy', DummyVecEnv([spaces_only] * n_envs), buffer_size=100,
                   learning_starts=4, batch_size=4, train_freq=4, seed=1, device='cpu')

    # the probe: SB3 collects whole rollouts of 4 vector steps past a budget of 10 steps
    assert model(DQN).learn(10).num_timesteps == 4 * n_envs * -(-10 // (4 * n_envs))
    ours = model(learner_class(None, LearnerSpec(n_steps=1))).learn(10)
    assert ours.num_timesteps == 10 and ours._n_updates == 2  # after 8 steps, and after the
    # short last rollout too
    ours.learn(7, reset_num_timesteps=False)  # a resume of a run stopped mid-rollout
    assert ours.num_timesteps == 17 + (n_envs == 2)  # a vector step is whole: 18 with 2 envs


# --- the auxiliary depth loss (issue 30): targets beside the observations, never in them --------
def _depth_buffers():
    from nav_gym.training.aux_depth import DepthFrameStackReplayBuffer, DepthReplayBuffer
    from nav_gym.training.learner import (
        DepthPrioritizedFrameStackReplayBuffer,
        DepthPrioritizedReplayBuffer,
    )
    one = spaces.Box(-1e6, 1e6, (1,), np.float32)
    return {
        'n-step, 2 envs': (DepthReplayBuffer, one, 2, {}),
        'prioritized': (DepthPrioritizedReplayBuffer, one, 1, {}),
        'frame stack, 2 envs': (DepthFrameStackReplayBuffer,
                                spaces.Box(-1e6, 1e6, (2,), np.float32), 2, {'frame_stack': 2}),
        'prioritized frame stack': (DepthPrioritizedFrameStackReplayBuffer,
                                    spaces.Box(-1e6, 1e6, (2,), np.float32), 1,
                                    {'frame_stack': 2}),
    }


@pytest.mark.parametrize('name', list(_depth_buffers()))
def test_each_sampled_observation_gets_its_own_depth_and_a_first_frame_none(name):
    import pickle
    cls, space, n_envs, extra = _depth_buffers()[name]
    buffer = cls(64, space, ACTIONS, device='cpu', n_envs=n_envs, n_steps=3, gamma=0.5,
                 **extra)
    expected = {}  # an observation's value: its depth (NaN: an episode's first frame)
    first = [True] * n_envs
    ends = {(0, 4), (1, 7), (0, 11)}
    for t in range(30):
        values = [1000.0 * e + t for e in range(n_envs)]
        for e, v in enumerate(values):
            expected[v] = np.nan if first[e] else v
        dones = np.array([(e, t) in ends for e in range(n_envs)])
        # the step's info holds the depth of the frame it led to (the next observation)
        infos = [{'depth': np.full(DEPTH_SHAPE, v + 1.0, np.float32)} for v in values]
        obs = np.array([[v - 1.0, v] if space.shape[0] == 2 else [v] for v in values],
                       np.float32)
        buffer.add(obs, obs + 1.0, np.ones((n_envs, 1)), np.zeros(n_envs), dones, infos)
        first = list(dones)  # after an end, the next frame begins an episode
    np.random.seed(3)
    for _ in range(5):
        samples = buffer.sample(32)
        newest = samples.observations[:, -1].numpy()
        got = buffer.last_depths
        assert got.shape == (32, DEPTH_SHAPE[0] * DEPTH_SHAPE[1])
        want = np.array([expected[v] for v in newest])
        np.testing.assert_array_equal(got[:, 0], want)  # NaN where NaN, equal elsewhere
        np.testing.assert_array_equal(got, np.repeat(got[:, :1], got.shape[1], axis=1))
    assert np.isnan(list(expected.values())).sum() == 1 * n_envs + len(
        [e for e in ends if e[0] < n_envs])
    # a loaded buffer resumes a run: the frame after its newest begins an episode
    assert not np.isnan(buffer.pending).all()
    assert np.isnan(pickle.loads(pickle.dumps(buffer)).pending).all()


def _depth_env(spaces_only):
    class WithDepth(spaces_only):
        def step(self, action):
            obs, reward, terminated, truncated, info = super().step(action)
            # a target the network can learn: the frame's mean brightness
            info['depth'] = np.full(DEPTH_SHAPE, obs.mean() / 255.0 * 3.0, np.float32)
            return obs, reward, terminated, truncated, info
    return WithDepth


@pytest.mark.parametrize('memory', [False, True])
def test_an_episodes_first_frame_gets_the_depth_of_its_reset(spaces_only, memory):
    from stable_baselines3.common.vec_env import DummyVecEnv

    from nav_gym.training.memory import FrameStackEnv

    class Episodes(_depth_env(spaces_only)):  # 7-step episodes; a reset's depth is 2.5 m
        def reset(self, *, seed=None, options=None):
            self.t = 0
            obs, info = super().reset(seed=seed, options=options)
            return obs, {**info, 'depth': np.full(DEPTH_SHAPE, 2.5, np.float32)}

        def step(self, action):
            self.t += 1
            obs, reward, _, truncated, info = super().step(action)
            return obs, reward, self.t % 7 == 0, truncated, info

    spec = LearnerSpec(aux_depth=1.0, frame_stack=2 if memory else 1, previous_action=False)
    envs = DummyVecEnv([Episodes, Episodes])
    model = learner_class(None, spec)(learner_policy(spec), FrameStackEnv(envs, 2) if memory
                                      else envs, buffer_size=200, learning_starts=100,
                                      batch_size=8, seed=1, device='cpu',
                                      **learner_kwargs(spec, 0.99))
    model.learn(40)  # 20 steps per env: three episodes begin in each
    depths = model.replay_buffer.depths[:model.replay_buffer.pos, :, 0]
    assert not np.isnan(depths).any()
    firsts = depths[[0, 7, 14]]  # the transitions that start from an episode's first frame
    assert (firsts == 2.5).all() and (np.delete(depths, [0, 7, 14], axis=0) != 2.5).all()


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')
@pytest.mark.parametrize('dueling', [False, True])
def test_the_depth_head_trains_and_never_changes_the_action(tmp_path, spaces_only, dueling):
    import copy

    from nav_gym.training.learner import q_and_features
    spec = LearnerSpec(aux_depth=1.0, dueling=dueling, **WITHOUT_MEMORY)
    assert 'auxiliary depth loss of weight 1' in spec.describe() and not spec.vanilla
    model = learner_class(None, spec)(learner_policy(spec), _depth_env(spaces_only)(),
                                      buffer_size=200, learning_starts=40, batch_size=8,
                                      train_freq=4, seed=1, device='cpu',
                                      **learner_kwargs(spec, 0.99))
    head = copy.deepcopy(model.q_net.depth_head.state_dict())
    model.learn(160)
    assert model._n_updates > 0
    assert 'train/depth_loss' in model.logger.name_to_value
    trained = model.q_net.depth_head.state_dict()
    assert not th.equal(trained['weight'], head['weight'])  # the loss reached the head
    # the head is a training signal only: the Q-values, hence the actions, do not use it
    obs = th.as_tensor(np.stack([OBS.sample() for _ in range(16)]))
    without = copy.deepcopy(model.q_net)
    del without.depth_head
    with th.no_grad():
        values = model.q_net(model.policy.obs_to_tensor(obs.numpy())[0])
        assert th.equal(values, without(model.policy.obs_to_tensor(obs.numpy())[0]))
        assert th.equal(values, q_and_features(model.q_net,
                                               model.policy.obs_to_tensor(obs.numpy())[0])[0])
    model.save(tmp_path / 'model.zip')
    loaded = DQN.load(tmp_path / 'model.zip', device='cpu')  # the head comes back with it
    assert th.equal(loaded.q_net.depth_head.weight, model.q_net.depth_head.weight)
    assert (loaded.predict(obs.numpy(), deterministic=True)[0]
            == model.predict(obs.numpy(), deterministic=True)[0]).all()
