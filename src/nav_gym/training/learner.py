"""The learner: SB3's DQN with Double DQN targets, and the components each flag adds.

The default learner is "DQN (SB3) with Double DQN targets (van Hasselt et al. 2016), 3-step
returns", a 4-frame stack with the previous action and resets every 20,000 steps at a replay
ratio of 2 (:class:`nav_gym.training.spec.LearnerSpec`): SB3's ``DQN`` whose TD target lets the
online network pick the next action and the target network value it, instead of taking the
maximum of the target network's values (which overestimates where the actions' true values are
close: docs/experiments.md measured it here), on SB3's n-step replay buffer.  Each component
has a published basis and a flag in config/train.yaml (:data:`nav_gym.training.spec.COMPONENTS`
holds the value that turns it off); all of them off is the Double DQN learner, and
``double_q: false`` with all of them off (and ``gradient_steps: 1``) is SB3's own ``DQN``
untouched (the workshop's learner, bit for bit: config/workshop.yaml).

- ``n_steps``: n-step returns (Sutton 1988; Rainbow, Hessel et al. 2018), SB3's own
  ``NStepReplayBuffer``;
- ``dueling``: a dueling head, ``Q = V + A - mean(A)`` (Wang et al. 2016), on the CNN's features;
- ``augment_shift``: every sampled observation and next observation shifted at random by up to
  this many pixels with replicated edges (DrQ, Kostrikov et al. 2021; RAD, Laskin et al. 2020),
  both augmentations in :mod:`nav_gym.training.augment`;
- ``augment_colour``: the colours of every sampled observation and next observation jittered:
  brightness, contrast, saturation and hue (RAD, Laskin et al. 2020);
- ``prioritized_replay``: proportional prioritized replay with importance weights (Schaul et
  al. 2016);
- ``munchausen``: Munchausen DQN's target (Vieillard et al. 2020), the scaled log-policy of the
  action taken added to the reward and a soft value bootstrapped, in place of Double DQN's;
- ``reset_interval``: the online network's fully connected layers re-initialised every so many
  steps, against the primacy bias at a higher replay ratio (Nikishin et al. 2022);
- ``frame_stack``: the agent's last k frames as its input, replayed from single frames
  (:mod:`nav_gym.training.memory`; DRQN's comparison, Hausknecht & Stone 2015);
- ``recurrent``: the window of ``frame_stack`` frames read by an LSTM over each frame's CNN
  features instead of stacked into the first convolution (DRQN, Hausknecht & Stone 2015): the
  frames before the latest build its state from zero, as R2D2's burn-in does, but with the
  gradient through them (:mod:`nav_gym.training.recurrent`);
- ``aux_depth``: an auxiliary loss of this weight, a linear head on the online network's
  features predicting the camera's coarse depth of each sampled observation (Mirowski et al.
  2017; UNREAL, Jaderberg et al. 2017); the targets come from ``info['depth']`` into a buffer
  of their own (:class:`DepthTargets`), and acting never uses the head.

Everything else is SB3's: network, replay, exploration, target updates, the saved model format
(a checkpoint of any of these loads with ``DQN.load``).  One change is not a component but how
the optimiser runs: this learner's Adam is PyTorch's fused CPU/GPU kernel (``fused=True``), the
same update as SB3's default per-parameter loop, which took 8.9 of a gradient step's ~45 ms on
one CPU core here (benchmarks/bench_learner.py).
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.torch_layers import create_mlp
from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit
from stable_baselines3.dqn.policies import CnnPolicy, QNetwork
from torch import nn
from torch.nn import functional as F

from nav_gym.training.augment import random_colour, random_shift
from nav_gym.training.aux_depth import (
    DepthCnnPolicy,
    DepthFrameStackReplayBuffer,
    DepthReplayBuffer,
    add_depth_head,
    begin_depths,
    depth_loss,
)
from nav_gym.training.memory import FrameStackReplayBuffer, refuse_unstacked
from nav_gym.training.recurrent import recurrent_policy_kwargs
from nav_gym.training.replay import (  # SumTree: buffers pickled before name it here
    DepthPrioritizedFrameStackReplayBuffer,
    DepthPrioritizedReplayBuffer,
    PrioritizedFrameStackReplayBuffer,
    PrioritizedReplayBuffer,
    SumTree,  # noqa: F401
)
from nav_gym.training.resets import reset_fully_connected
from nav_gym.training.spec import COMPONENTS, LearnerSpec
from nav_gym.training.targets import double_q_target, max_q_target, munchausen_target


def dueling_q(values: th.Tensor, advantages: th.Tensor) -> th.Tensor:
    """Combine ``V (N, 1)`` and ``A (N, actions)`` into ``Q = V + A - mean(A)`` (Wang et al.)."""
    return values + advantages - advantages.mean(dim=1, keepdim=True)


class DuelingQNetwork(QNetwork):
    """SB3's Q-network with a dueling head: a value and an advantage stream on the features."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """Build SB3's Q-network (its head becomes the advantage stream) and a value stream."""
        super().__init__(*args, **kwargs)
        self.value_net = nn.Sequential(*create_mlp(self.features_dim, 1, self.net_arch,
                                                   self.activation_fn))

    def forward(self, obs: th.Tensor) -> th.Tensor:
        """Return the Q-values ``V + A - mean(A)``."""
        features = self.extract_features(obs, self.features_extractor)
        return dueling_q(self.value_net(features), self.q_net(features))


class DuelingCnnPolicy(CnnPolicy):
    """SB3's ``CnnPolicy`` for DQN whose online and target networks have a dueling head."""

    def make_q_net(self) -> QNetwork:
        """Return a :class:`DuelingQNetwork` with its own features extractor."""
        net_args = self._update_features_extractor(self.net_args, features_extractor=None)
        return DuelingQNetwork(**net_args).to(self.device)


def q_and_features(net: QNetwork, obs: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
    """Return a Q-network's values and the features they come from, in one forward pass."""
    features = net.extract_features(obs, net.features_extractor)
    if isinstance(net, DuelingQNetwork):
        return dueling_q(net.value_net(features), net.q_net(features)), features
    return net.q_net(features), features


class DepthDuelingCnnPolicy(DuelingCnnPolicy):
    """The dueling policy whose Q-networks also carry the auxiliary depth head."""

    def make_q_net(self) -> QNetwork:
        """Return the dueling Q-network with a depth head."""
        return add_depth_head(super().make_q_net())


class Learner(DQN):
    """SB3's DQN whose gradient step adds the Double DQN target and the enabled components.

    ``learner`` (a :class:`LearnerSpec`) says which; it is saved with the model, so a resumed
    run trains the same learner, and a checkpoint loads with ``DQN.load`` as any other.
    """

    def __init__(self, *args: Any, learner: LearnerSpec | None = None, **kwargs: Any) -> None:
        """Create SB3's DQN; ``learner`` defaults to the Double DQN learner (no component)."""
        self.learner = learner or LearnerSpec(**COMPONENTS)
        self.resets = 0  # of the fully connected layers so far (reset_interval)
        super().__init__(*args, **kwargs)

    def _setup_model(self) -> None:
        """SB3's set-up, after checking that a learner with memory sees the agent's stacks."""
        spec = self.learner
        if spec.memory:
            refuse_unstacked(self.observation_space, spec.frame_stack,
                             int(self.action_space.n) if spec.previous_action else 0)
        super()._setup_model()

    def _on_step(self) -> None:
        """SB3's step bookkeeping, then a reset when one is due (``reset_interval``).

        Counted in vector steps as SB3 counts its target updates, only once learning has begun,
        and only where a whole interval of training follows before the end: a reset never
        leaves the final model an untrained head.  :mod:`nav_gym.training.resets` says what a
        reset does.
        """
        super()._on_step()
        interval = self.learner.reset_interval
        if (interval and self.learning_starts < self.num_timesteps
                and self.num_timesteps + interval <= self._total_timesteps
                and self._n_calls % max(interval // self.n_envs, 1) == 0):
            reset_fully_connected(self.q_net, self.policy.optimizer)
            self.resets += 1
            self.logger.record('train/resets', self.resets)

    def _setup_learn(self, *args: Any, **kwargs: Any) -> Any:
        """SB3's set-up; where it reset the envs, their first frames' depths (``aux_depth``)."""
        before = self._last_obs
        result = super()._setup_learn(*args, **kwargs)
        if self._last_obs is not before:
            begin_depths(self.replay_buffer, self.env, range(self.n_envs))
        return result

    def collect_rollouts(self, env: Any, callback: Any, train_freq: TrainFreq, *args: Any,
                         **kwargs: Any) -> Any:
        """SB3's collection of ``train_freq`` steps, the last rollout cut to the budget's rest.

        SB3 collects a whole ``train_freq`` whatever the budget has left, so a run whose
        budget is not a multiple of ``train_freq`` vector steps overshot it: a resume from a
        Ctrl-C mid-rollout ended at 200,001 of 200,000 steps, and ``n_envs: 3`` (4 vector steps
        a rollout, ``vector_schedule``) would end 50,000 at 50,004.  Now a run ends at its budget
        (within ``n_envs - 1``: a vector step is whole), and the short last rollout still gets
        its gradient steps.  A budget that is a
        multiple is collected as before, bit for bit.  SB3's vanilla ``DQN`` keeps SB3's rule.
        """
        left = -(-(self._total_timesteps - self.num_timesteps) // env.num_envs)  # vector steps
        if train_freq.unit == TrainFrequencyUnit.STEP and 0 < left < train_freq.frequency:
            train_freq = TrainFreq(left, train_freq.unit)
        return super().collect_rollouts(env, callback, train_freq, *args, **kwargs)

    def _store_transition(self, replay_buffer: Any, buffer_action: Any, new_obs: Any,
                          reward: Any, dones: Any, infos: Any) -> None:
        """SB3's; then each new episode's first frame's depth (``aux_depth``)."""
        super()._store_transition(replay_buffer, buffer_action, new_obs, reward, dones, infos)
        begin_depths(replay_buffer, self.env, np.flatnonzero(dones))

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        """Run ``gradient_steps`` gradient steps: SB3's ``DQN.train`` with the spec's changes."""
        spec = self.learner
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        buffer = self.replay_buffer
        prioritized = isinstance(buffer, PrioritizedReplayBuffer)
        if prioritized:  # beta anneals linearly to 1 over training (Schaul et al.)
            progress = 1.0 - self._current_progress_remaining
            buffer.beta = spec.priority_beta + (1.0 - spec.priority_beta) * progress
        losses, depth_losses = [], []
        for _ in range(gradient_steps):
            data = buffer.sample(batch_size, env=self._vec_normalize_env)
            discounts = data.discounts if data.discounts is not None else self.gamma
            obs, next_obs = data.observations, data.next_observations
            if spec.augment_shift:
                obs = random_shift(obs, spec.augment_shift)
                next_obs = random_shift(next_obs, spec.augment_shift)
            if spec.augment_colour:
                obs = random_colour(obs, spec.augment_colour, spec.frame_stack)
                next_obs = random_colour(next_obs, spec.augment_colour, spec.frame_stack)
            with th.no_grad():
                next_q_target = self.q_net_target(next_obs)
                if spec.munchausen:
                    target = munchausen_target(data.rewards, data.dones, discounts,
                                               self.q_net_target(obs), data.actions,
                                               next_q_target)
                elif spec.double_q:
                    target = double_q_target(data.rewards, data.dones, discounts,
                                             self.q_net(next_obs), next_q_target)
                else:
                    target = max_q_target(data.rewards, data.dones, discounts, next_q_target)
            values, features = q_and_features(self.q_net, obs)  # the features: aux_depth's
            current = th.gather(values, dim=1, index=data.actions.long())
            if prioritized:
                weights = th.as_tensor(buffer.last_weights, device=self.device).reshape(-1, 1)
                loss = (weights * F.smooth_l1_loss(current, target, reduction='none')).mean()
                buffer.update_priorities(buffer.last_indices,
                                         (current - target).detach().reshape(-1).cpu().numpy())
            else:
                loss = F.smooth_l1_loss(current, target)
            if spec.aux_depth:
                targets = th.as_tensor(buffer.last_depths, device=self.device)
                aux = depth_loss(self.q_net, features, targets)
                depth_losses.append(aux.item())
                loss = loss + spec.aux_depth * aux
            losses.append(loss.item())
            self.policy.optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record('train/n_updates', self._n_updates, exclude='tensorboard')
        self.logger.record('train/loss', np.mean(losses))
        if depth_losses:
            self.logger.record('train/depth_loss', np.mean(depth_losses))


# the replay buffer of a learner with memory, by (aux_depth, prioritized_replay)
BUFFERS = {(False, False): FrameStackReplayBuffer,
           (True, False): DepthFrameStackReplayBuffer,
           (False, True): PrioritizedFrameStackReplayBuffer,
           (True, True): DepthPrioritizedFrameStackReplayBuffer}


def learner_kwargs(spec: LearnerSpec, gamma: float) -> dict[str, Any]:
    """Return what ``DQN(...)`` needs for this learner beyond the hyperparameters.

    Nothing for the vanilla learner (SB3's DQN as it is); otherwise the fused Adam, the learner
    spec, and the replay buffer of n-step returns or prioritized replay.
    """
    if spec.vanilla:
        return {}
    kwargs: dict[str, Any] = {'policy_kwargs': {'optimizer_kwargs': {'fused': True}},
                              'learner': spec}
    depth = bool(spec.aux_depth)
    if spec.memory:  # single frames in the buffer, stacks rebuilt at sample time
        kwargs['replay_buffer_class'] = BUFFERS[depth, spec.prioritized_replay]
        kwargs['replay_buffer_kwargs'] = {'frame_stack': spec.frame_stack,
                                          'previous_action': spec.previous_action,
                                          'n_steps': spec.n_steps, 'gamma': gamma}
        if spec.prioritized_replay:
            kwargs['replay_buffer_kwargs'].update(alpha=spec.priority_alpha,
                                                  beta=spec.priority_beta)
        if spec.recurrent:  # the window read by an LSTM, not stacked into the first conv
            kwargs['policy_kwargs'].update(recurrent_policy_kwargs(
                spec.frame_stack, spec.recurrent, spec.previous_action))
    elif spec.prioritized_replay:
        kwargs['replay_buffer_class'] = (DepthPrioritizedReplayBuffer if depth
                                         else PrioritizedReplayBuffer)
        kwargs['replay_buffer_kwargs'] = {'alpha': spec.priority_alpha,
                                          'beta': spec.priority_beta,
                                          'n_steps': spec.n_steps, 'gamma': gamma}
    elif depth:
        kwargs['replay_buffer_class'] = DepthReplayBuffer
        kwargs['replay_buffer_kwargs'] = {'n_steps': spec.n_steps, 'gamma': gamma}
    else:
        kwargs['n_steps'] = spec.n_steps
    return kwargs


def learner_policy(spec: LearnerSpec) -> str | type:
    """Return the policy ``DQN(...)`` builds: SB3's CnnPolicy, or the dueling one."""
    if spec.aux_depth:
        return DepthDuelingCnnPolicy if spec.dueling else DepthCnnPolicy
    return DuelingCnnPolicy if spec.dueling else 'CnnPolicy'


def learner_class(timing: Any | None = None, spec: LearnerSpec | None = None) -> type:
    """Return the class that trains ``spec``, counting its work into ``timing``.

    SB3's ``DQN`` for the vanilla learner, else :class:`Learner`.  ``timing`` is the env's step
    budget (``env.timing``): ``train`` (gradient steps) and ``predict`` calls become the
    learner's share of every env step.  A subclass, not wrappers set on the model, so the timing
    never becomes model state that saving would pickle; a checkpoint of it loads with
    ``DQN.load`` as any other.  Without ``timing`` the class itself is returned, untimed.
    """
    base = DQN if (spec or LearnerSpec()).vanilla else Learner
    if timing is None:
        return base

    class TimedDQN(base):  # type: ignore[misc, valid-type]
        """The learner with its ``train`` and ``predict`` timed."""

        def train(self, *args: Any, **kwargs: Any) -> Any:
            """Run the learner's gradient steps, timed as ``gradient_step``."""
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


def load_checkpoint(path: Path, spec: LearnerSpec | None = None, timing: Any | None = None,
                    **kwargs: Any) -> Any:
    """Load a checkpoint with the class that trains ``spec`` (SB3's ``DQN`` without one).

    SB3 warns that ``n_steps`` "is ignored" whenever it loads a saved n-step model (the buffer
    class it saved already is the n-step one): the warning is silenced here.  A resumed run
    trains the learner its config names (``spec``), whatever the checkpoint saved.
    """
    cls = learner_class(timing, spec) if spec is not None else DQN
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', message='`n_steps=.*` is ignored because a custom')
        model = cls.load(path, **kwargs)
    if spec is not None and isinstance(model, Learner):
        model.learner = spec
    return model
