"""The memory learner on SB3: the agent's stacks, and the replay buffer that rebuilds them."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.vec_env import DummyVecEnv

from nav_gym.training.memory import FrameStackEnv, FrameStackReplayBuffer, stacked_space
from nav_gym.training.recurrent import RecurrentCnn


class Counter(gym.Env):
    """Frames that name their env and time step; episodes of 1-5 steps (ends and time-outs)."""

    observation_space = spaces.Box(0, 255, (3, 4, 4), np.uint8)
    action_space = spaces.Discrete(3)

    def __init__(self, tag: int) -> None:
        self.tag, self.t, self.left = tag, 0, 0
        self.rng = np.random.default_rng(tag)

    def _frame(self) -> np.ndarray:
        self.t += 1
        frame = np.zeros((3, 4, 4), np.uint8)
        frame[0], frame[1], frame[2] = self.tag, self.t % 256, self.t // 256
        return frame

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.left = int(self.rng.integers(1, 6))
        return self._frame(), {}

    def step(self, action):
        self.left -= 1
        ended = self.left == 0
        terminated = ended and self.t % 2 == 0
        return self._frame(), 1.0, terminated, ended and not terminated, {}


def frame_time(frame: np.ndarray) -> int:
    """Return the time step a Counter frame names."""
    return int(frame[1, 0, 0]) + 256 * int(frame[2, 0, 0])


def test_the_agent_stacks_its_frames_and_begins_afresh_at_each_episode():
    envs = FrameStackEnv(DummyVecEnv([lambda: Counter(1)]), 3)
    first = envs.reset()[0]
    assert first.shape == (9, 4, 4) and [first[c, 0, 0] for c in (1, 4, 7)] == [1, 1, 1]
    for _ in range(20):
        obs, _, dones, infos = envs.step(np.array([1]))
        if dones[0]:
            terminal = infos[0]['terminal_observation']
            assert terminal.shape == (9, 4, 4)
            # the new episode's first frame stands in for the frames before it
            assert obs[0][1, 0, 0] == obs[0][4, 0, 0] == obs[0][7, 0, 0]
            assert terminal[7, 0, 0] != obs[0][7, 0, 0]


def test_the_previous_action_follows_the_frames_as_planes_none_at_an_episode_start():
    envs = FrameStackEnv(DummyVecEnv([lambda: Counter(1)]), 2, previous_action=True)
    assert envs.observation_space.shape == (9, 4, 4)
    assert envs.observation_space.high[6:].min() == 255 == envs.observation_space.high.max()
    first = envs.reset()[0]
    assert not first[6:].any()  # no action yet
    rng = np.random.default_rng(0)
    for _ in range(30):
        action = int(rng.integers(3))
        obs, _, dones, infos = envs.step(np.array([action]))
        led_to = infos[0]['terminal_observation'] if dones[0] else obs[0]
        assert [int(led_to[6 + a, 0, 0]) for a in range(3)] == [
            255 * (a == action) for a in range(3)]
        if dones[0]:
            assert not obs[0][6:].any()  # the next episode's first frame: none


@pytest.mark.parametrize(('k', 'previous_action'), [(1, False), (4, False), (1, True),
                                                    (3, True)])
def test_the_buffer_keeps_single_frames_and_samples_the_stacks_added(k, previous_action):
    n_envs, size = 2, 40
    envs = FrameStackEnv(DummyVecEnv([lambda i=i: Counter(i + 1) for i in range(n_envs)]), k,
                         previous_action)
    buffer = FrameStackReplayBuffer(size, envs.observation_space, envs.action_space,
                                    device='cpu', n_envs=n_envs, frame_stack=k, n_steps=1,
                                    previous_action=previous_action)
    assert buffer.observations.frames.shape == (size // n_envs, n_envs, 3, 4, 4)
    newest = slice(3 * (k - 1), 3 * k)  # the newest frame's channels in a stack
    rows = size // n_envs
    added = {}  # (position, env) -> (stacked obs, stacked next obs) of the newest writes
    stored = [{} for _ in range(n_envs)]  # per env: a frame's time -> the step it was stored
    obs = envs.reset()
    rng = np.random.default_rng(k)
    for step in range(3 * rows + 5):  # wraps the buffer three times
        actions = rng.integers(0, 3, n_envs)
        nxt, rewards, dones, infos = envs.step(actions)
        real_next = nxt.copy()
        for e in range(n_envs):
            if dones[e]:
                real_next[e] = infos[e]['terminal_observation']
        position = buffer.pos
        buffer.add(obs, real_next, actions, rewards, dones, infos)
        for e in range(n_envs):
            added[(position, e)] = (obs[e].copy(), real_next[e].copy(), step)
            stored[e][frame_time(obs[e][newest])] = step  # the vector step it was stored at
        obs = nxt
    newest_step = 3 * rows + 4
    checked = 0
    for (position, e), (stacked, stacked_next, _) in added.items():
        got = buffer.observations[np.array([position]), np.array([e])][0]
        got_next = buffer.next_observations[np.array([position]), np.array([e])][0]
        assert np.array_equal(got_next[newest], stacked_next[newest])
        assert np.array_equal(got_next[3 * k:], stacked_next[3 * k:])  # the stored action
        # every frame of the stack still kept (and the action before the newest, unless none
        # was taken in its episode yet): the stacks acting saw
        oldest_kept = newest_step - rows + 1
        action_kept = (not stacked[3 * k:].any()
                       or stored[e][frame_time(stacked[newest])] > oldest_kept)
        if stored[e][frame_time(stacked[:3])] >= oldest_kept and action_kept:
            assert np.array_equal(got, stacked), (position, e)
            assert np.array_equal(got_next, stacked_next), (position, e)
            checked += 1
    assert checked > rows  # most positions are checked
    channels = 3 * k + 3 * previous_action
    samples = buffer.sample(8)
    assert samples.observations.shape == (8, channels, 4, 4)
    assert samples.next_observations.shape == (8, channels, 4, 4)


def test_a_dqn_trains_on_stacks_with_a_single_frame_buffer(spaces_only):
    envs = FrameStackEnv(DummyVecEnv([spaces_only]), 4)
    model = DQN('CnnPolicy', envs, buffer_size=200, learning_starts=40, batch_size=8,
                replay_buffer_class=FrameStackReplayBuffer,
                replay_buffer_kwargs={'frame_stack': 4, 'n_steps': 3, 'gamma': 0.99},
                seed=1, device='cpu')
    model.learn(100)
    assert model._n_updates > 0
    assert model.observation_space.shape == (12, 84, 84)
    assert model.replay_buffer.observations.frames.shape[2:] == (3, 84, 84)


def two_episodes(spec, envs, tmp_path):  # noqa: ANN001, ANN201
    """Train ``spec`` briefly on ``envs``; act as its DQNActor: two frames, a new episode, one.

    Returns the model and, per decision, the raw uint8 input its network saw and the action.
    """
    from nav_gym.policy.actors import DQNActor
    from nav_gym.training.learner import learner_class, learner_kwargs, learner_policy
    model = learner_class(None, spec)(learner_policy(spec), envs, buffer_size=200,
                                      learning_starts=40, batch_size=8, seed=1, device='cpu',
                                      **learner_kwargs(spec, 0.99))
    model.learn(60)
    assert model._n_updates > 0
    model.save(tmp_path / 'model.zip')
    actor = DQNActor(tmp_path / 'model.zip')
    seen = []
    network = actor.model.q_net
    actor.model.q_net = lambda tensor: seen.append(tensor.clone()) or network(tensor)
    frames = [np.full((3, 84, 84), value, np.uint8) for value in (10, 20, 30)]
    actor.begin_episode(1)
    actions = [actor.act(frames[0])[0], actor.act(frames[1])[0]]
    actor.begin_episode(2)  # a new episode: the history begins again
    actions.append(actor.act(frames[2])[0])
    return model, list(zip(seen, actions, strict=True))


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')
def test_an_actor_of_a_frame_stack_learner_keeps_and_begins_its_history(spaces_only, tmp_path):
    import torch

    from nav_gym.policy.export import export_policy
    from nav_gym.training.spec import LearnerSpec

    spec = LearnerSpec(frame_stack=2, previous_action=False)
    _, decisions = two_episodes(spec, FrameStackEnv(DummyVecEnv([spaces_only]), 2), tmp_path)
    assert 'a 2-frame stack (Hausknecht & Stone 2015)' in spec.describe()
    firsts = [[int(t[0, c, 0, 0]) for c in (0, 3)] for t, _ in decisions]  # the raw stacks
    assert firsts == [[10, 10], [10, 20], [30, 30]]
    assert all(t.shape == torch.Size([1, 6, 84, 84]) for t, _ in decisions)
    # it exports (its stack is the network's input, tests/nav_gym/policy/test_export.py)
    assert export_policy(tmp_path / 'model.zip', tmp_path / 'export').meta['input'][
        'shape'] == [1, 6, 84, 84]


def test_a_memory_learner_refuses_an_env_outside_the_agents_stacks(spaces_only):
    from nav_gym.training.learner import learner_class, learner_kwargs, learner_policy
    from nav_gym.training.spec import LearnerSpec

    spec = LearnerSpec()  # the default learner remembers: 4 frames and the previous action
    with pytest.raises(ValueError, match=r'\(3, 84, 84\) are not 4-frame stacks with 3 action '
                                         'planes: .* FrameStackEnv'):  # once a 0-channel buffer
        learner_class(None, spec)(learner_policy(spec), spaces_only(), buffer_size=16,
                                  device='cpu', **learner_kwargs(spec, 0.99))
    three = LearnerSpec(frame_stack=3, previous_action=False)  # (3, 84, 84): 3 frames of 1?
    with pytest.raises(ValueError, match='not 3-frame stacks with 0 action planes'):
        learner_class(None, three)(learner_policy(three), spaces_only(), buffer_size=16,
                                   device='cpu', **learner_kwargs(three, 0.99))
    stacked = FrameStackEnv(DummyVecEnv([spaces_only]), 4, previous_action=True)
    assert learner_class(None, spec)(learner_policy(spec), stacked, buffer_size=16,
                                     device='cpu', **learner_kwargs(spec, 0.99)
                                     ).observation_space.shape == (15, 84, 84)


def test_prioritized_replay_samples_the_stacks_of_the_transitions_it_weighs():
    from nav_gym.training.replay import PrioritizedFrameStackReplayBuffer

    k, size = 3, 30
    envs = FrameStackEnv(DummyVecEnv([lambda: Counter(5)]), k, previous_action=True)
    buffer = PrioritizedFrameStackReplayBuffer(size, envs.observation_space, envs.action_space,
                                               device='cpu', frame_stack=k, n_steps=1,
                                               previous_action=True, alpha=1.0, beta=1.0)
    assert buffer.observations.frames.shape == (size, 1, 3, 4, 4)  # single frames
    added = {}
    obs = envs.reset()
    for step in range(20):
        action = np.array([step % 3])
        nxt, rewards, dones, infos = envs.step(action)
        real_next = np.array([infos[0]['terminal_observation'] if dones[0] else nxt[0]])
        added[buffer.pos] = (obs[0].copy(), real_next[0].copy())
        buffer.add(obs, real_next, action, rewards, dones, infos)
        obs = nxt
    buffer.update_priorities(np.arange(20), np.r_[np.full(19, 1e-3), 10.0])  # the newest
    np.random.seed(0)
    samples = buffer.sample(16)
    assert np.mean(buffer.last_indices == 19) > 0.9  # drawn by its priority
    for i, position in enumerate(buffer.last_indices):  # each sample: its transition's stacks
        stacked, stacked_next = added[int(position)]
        assert np.array_equal(samples.observations[i].numpy(), stacked)
        assert np.array_equal(samples.next_observations[i].numpy(), stacked_next)
    assert buffer.last_weights.max() == 1.0 and buffer.last_weights.min() > 0


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')
def test_an_actor_feeds_back_its_previous_action_begun_afresh_at_each_episode(spaces_only,
                                                                               tmp_path):
    from nav_gym.training.spec import LearnerSpec

    spec = LearnerSpec(frame_stack=1, previous_action=True)  # memory of what it did, one frame
    model, decisions = two_episodes(spec, FrameStackEnv(DummyVecEnv([spaces_only]), 1,
                                                        previous_action=True), tmp_path)
    assert model.observation_space.shape == (6, 84, 84)
    assert 'the previous action as input (Mirowski et al. 2017)' in spec.describe()
    planes = [[int(t[0, 3 + a, 0, 0]) for a in range(3)] for t, _ in decisions]  # raw uint8
    first = decisions[0][1]
    assert planes == [[0, 0, 0], [255 * (a == first) for a in range(3)], [0, 0, 0]]
    assert [int(t[0, 0, 0, 0]) for t, _ in decisions] == [10, 20, 30]
    # exploring, the action taken is the previous one, not the greedy one it replaced
    from nav_eval.evaluation.policies import ExploringDQNPolicy
    explorer = ExploringDQNPolicy(tmp_path / 'model.zip', epsilon=1.0)
    seen = []
    network = explorer.model.q_net
    explorer.model.q_net = lambda tensor: seen.append(tensor.clone()) or network(tensor)
    explorer.begin_episode(3)
    taken = [explorer.act(np.full((3, 84, 84), 10 * i, np.uint8))[0] for i in range(8)]
    greedy = [int(network(t).argmax()) for t in seen]
    assert taken != greedy  # the probe: some random action replaced the greedy one
    assert [[int(t[0, 3 + a, 0, 0]) for a in range(3)] for t in seen[1:]] == [
        [255 * (a == action) for a in range(3)] for action in taken[:-1]]


def test_a_resume_ends_the_running_episodes_for_n_step_returns_and_memory():
    """A resumed run's envs start new episodes: the buffer's newest transitions end there.

    A running episode ends as a time-out (bootstrapped), an ended one stays as it was; the new
    episode's first stack begins afresh, and no n-step return reaches across.
    """
    from nav_gym.training.checkpoints import cut_at_resume
    n_envs, gamma = 2, 0.9
    envs = FrameStackEnv(DummyVecEnv([lambda i=i: Counter(i + 7) for i in range(n_envs)]), 2,
                         previous_action=True)
    buffer = FrameStackReplayBuffer(40, envs.observation_space, envs.action_space,
                                    device='cpu', n_envs=n_envs, frame_stack=2, n_steps=3,
                                    gamma=gamma, previous_action=True)
    obs = envs.reset()
    for _ in range(6):
        actions = np.array([2, 0])
        nxt, rewards, _, _ = envs.step(actions)
        dones = np.zeros(n_envs, bool)  # every episode still running at the save ...
        buffer.add(obs, nxt, actions, rewards, dones, [{} for _ in range(n_envs)])
        obs = nxt
    last = buffer.pos - 1
    buffer.dones[last, 1] = 1.0  # ... but env 1's, which has just ended (terminated)
    cut_at_resume(buffer)
    assert list(buffer.dones[last]) == [1.0, 1.0] and list(buffer.timeouts[last]) == [1.0, 0.0]
    obs = envs.reset()  # the resumed run: new episodes
    nxt, rewards, dones, infos = envs.step(np.array([1, 1]))
    buffer.add(obs, nxt, np.array([1, 1]), rewards, dones, infos)
    first = buffer.observations[np.array([buffer.pos - 1] * 2), np.arange(n_envs)]
    assert np.array_equal(first, obs)  # begun afresh: the first frame twice, no action
    assert not first[:, 6:].any()
    np.random.seed(0)
    sampled_envs = np.random.randint(0, n_envs, 8)  # the envs SB3 draws below
    np.random.seed(0)
    samples = buffer._get_samples(np.array([last] * 8))
    assert set(sampled_envs) == {0, 1}
    assert np.allclose(samples.discounts.numpy(), gamma)  # one step, then the cut
    # env 0 was cut (a time-out: bootstrapped), env 1 terminated (not)
    assert list(samples.dones.numpy().reshape(-1)) == [float(e == 1) for e in sampled_envs]


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')
def test_a_memory_learner_jitters_its_stacks_frames_and_keeps_their_action_planes(
        spaces_only, monkeypatch):
    from nav_gym.training import learner
    from nav_gym.training.learner import learner_class, learner_kwargs, learner_policy
    from nav_gym.training.spec import LearnerSpec

    calls = []
    from nav_gym.training.augment import random_colour

    def spy(images, strength, frames=1, generator=None):  # noqa: ANN001, ANN202
        out = random_colour(images, strength, frames, generator)
        calls.append((images, strength, frames, out))
        return out

    monkeypatch.setattr(learner, 'random_colour', spy)
    spec = LearnerSpec(frame_stack=2, previous_action=True, augment_colour=0.3)
    envs = FrameStackEnv(DummyVecEnv([spaces_only]), 2, previous_action=True)
    model = learner_class(None, spec)(learner_policy(spec), envs, buffer_size=200,
                                      learning_starts=40, batch_size=8, seed=1, device='cpu',
                                      **learner_kwargs(spec, 0.99))
    model.learn(60)
    assert model._n_updates > 0 and len(calls) == 2 * model._n_updates  # obs, next obs
    for images, strength, frames, out in calls:
        assert (strength, frames, images.shape[1]) == (0.3, 2, 9)
        assert th.equal(out[:, 6:], images[:, 6:].float())  # the action planes, as they were
        assert not th.equal(out[:, :6], images[:, :6].float())  # the probe: frames jittered


# the recurrent Q-network (recurrent): an LSTM over the same window, in training and acting

def window(k: int, n_actions: int = 0) -> spaces.Box:
    """Return the space of a window of k (3, 84, 84) frames and n_actions planes."""
    return stacked_space(spaces.Box(0, 255, (3, 84, 84), np.uint8), k, n_actions)


def test_the_lstm_reads_the_window_oldest_first_from_a_zero_state_its_burn_in():
    th.manual_seed(0)
    net = RecurrentCnn(window(3, 3), frames=3, hidden=16, previous_action=True)
    assert net.features_dim == 16 + 3 and net.n_actions == 3
    obs = th.rand(2, 12, 84, 84)
    obs[:, 9:] = th.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])[:, :, None, None]
    out = net(obs)
    # by hand: each frame through the CNN, the LSTM stepped from zeros, oldest frame first
    state = (th.zeros(1, 2, 16), th.zeros(1, 2, 16))
    for f in range(3):
        step, state = net.lstm(net.cnn(obs[:, 3 * f:3 * f + 3])[:, None], state)
    assert th.allclose(out[:, :16], step[:, 0], atol=1e-6)
    assert out[:, 16:].tolist() == [[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]  # the previous action
    # the burn-in counts: the oldest frame changes the output, the action planes' rest do not
    older = obs.clone()
    older[:, :3] = th.rand(2, 3, 84, 84)
    assert not th.allclose(net(older)[:, :16], out[:, :16])
    planes = obs.clone()
    planes[:, 9:, 1:] = 0.5
    assert th.equal(net(planes), out)
    # and it is trained: the loss on the latest output reaches the oldest frame (not detached)
    older.requires_grad_(True)
    net(older)[:, :16].sum().backward()
    assert older.grad[:, :3].abs().sum() > 0


def test_a_window_needs_two_frames_and_the_flag_needs_a_stack():
    from nav_gym.errors import TrainConfigError
    from nav_gym.training.config import TrainConfig

    with pytest.raises(ValueError, match='at least 2 frames'):
        RecurrentCnn(window(1), frames=1, hidden=8)
    with pytest.raises(ValueError, match='not a window of 4 frames'):
        RecurrentCnn(window(3), frames=4, hidden=8)
    with pytest.raises(ValueError, match='not a window of 3 frames and action planes'):
        RecurrentCnn(window(3), frames=3, hidden=8, previous_action=True)
    with pytest.raises(ValueError, match=r'\(12, 84, 84\) is not a window of 3 frames$'):
        RecurrentCnn(window(4), frames=3, hidden=8)  # a frame too many is no action planes
    with pytest.raises(TrainConfigError, match='set frame_stack to 2 or more'):
        TrainConfig(recurrent=64, frame_stack=1)
    assert ('a 4-frame stack (Hausknecht & Stone 2015), an LSTM of 64 units over the window '
            '(Hausknecht & Stone 2015)') in TrainConfig(recurrent=64).learner().describe()


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')
def test_a_recurrent_learner_trains_and_its_actor_and_export_begin_each_episode_afresh(
        spaces_only, tmp_path):
    from nav_gym.policy.export import export_policy
    from nav_gym.policy.exported import OnnxActor
    from nav_gym.training.spec import LearnerSpec

    spec = LearnerSpec(frame_stack=3, recurrent=32, previous_action=True)
    envs = FrameStackEnv(DummyVecEnv([spaces_only]), 3, previous_action=True)
    model, decisions = two_episodes(spec, envs, tmp_path)
    assert isinstance(model.q_net.features_extractor, RecurrentCnn)
    assert isinstance(model.replay_buffer, FrameStackReplayBuffer)  # windows of single frames
    assert model.replay_buffer.observations.frames.shape[2:] == (3, 84, 84)
    # the actor's windows: the new episode's first frame stands in for all three, no action
    firsts = [[int(t[0, c, 0, 0]) for c in (0, 3, 6)] for t, _ in decisions]
    assert firsts == [[10, 10, 10], [10, 10, 20], [30, 30, 30]]
    assert not decisions[2][0][0, 9:].any()
    # a Q head of one linear layer, as NatureCNN's (not SB3's 64-64 default for other extractors)
    assert [type(layer) for layer in model.q_net.q_net] == [th.nn.Linear]
    # no state carried over: a fresh actor's first decision on the frame sees the same window
    # and gives the same Q-values as the new episode's, after two decisions of another episode
    from nav_gym.policy.actors import DQNActor
    fresh = DQNActor(tmp_path / 'model.zip')
    seen = []
    network = fresh.model.q_net
    fresh.model.q_net = lambda tensor: seen.append(tensor.clone()) or network(tensor)
    fresh.begin_episode(7)
    action, q_values = fresh.act(np.full((3, 84, 84), 30, np.uint8))
    assert th.equal(seen[0], decisions[2][0]) and action == decisions[2][1]
    assert np.allclose(q_values, model.q_net(decisions[2][0]).detach().numpy()[0], atol=1e-5)
    # the ONNX export carries the window as its input and gives the same actions and Q-values
    exported = export_policy(tmp_path / 'model.zip', tmp_path / 'export')
    assert exported.meta['input']['shape'] == [1, 12, 84, 84]
    onnx = OnnxActor(exported)
    onnx.begin_episode(1)
    for value, (window_in, chosen) in zip((10, 20), decisions, strict=False):
        action, q_values = onnx.act(np.full((3, 84, 84), value, np.uint8))
        assert action == chosen
        assert np.allclose(q_values, network(window_in).detach().numpy()[0], atol=1e-4)
