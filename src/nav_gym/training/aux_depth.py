"""The auxiliary depth loss (``aux_depth``): its head, its loss and its replay targets.

Issue 30's second kind of help for a learner that must search (Mirowski et al. 2017; UNREAL,
Jaderberg et al. 2017): a linear head on the online network's CNN features predicts the camera's
coarse depth of each sampled observation (``info['depth']``, :mod:`nav_sim.core.depth`).  The
targets travel in ``info`` and a replay array of their own (:class:`DepthTargets`), never in the
observation; the head sits in the Q-network, so that the optimiser trains it and a checkpoint
keeps it, but the Q-values never use it.  :mod:`nav_gym.training.learner` adds the loss to the
TD loss and builds the dueling and prioritized variants.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples
from stable_baselines3.dqn.policies import CnnPolicy, QNetwork
from torch import nn
from torch.nn import functional as F

from nav_gym.training.memory import FrameStackReplayBuffer
from nav_sim.core.depth import DEPTH_KEY, DEPTH_RANGE, DEPTH_SHAPE

DEPTH_CELLS = DEPTH_SHAPE[0] * DEPTH_SHAPE[1]


def add_depth_head(net: QNetwork) -> QNetwork:
    """Give ``net`` the auxiliary depth head (``net.depth_head``: features to depth cells).

    A sub-module of the Q-network, so that the optimiser trains it and checkpoints keep it;
    the Q-values (``forward``) never use it.
    """
    net.depth_head = nn.Linear(net.features_dim, DEPTH_CELLS).to(net.device)
    return net


class DepthCnnPolicy(CnnPolicy):
    """SB3's ``CnnPolicy`` whose Q-networks also carry the auxiliary depth head."""

    def make_q_net(self) -> QNetwork:
        """Return SB3's Q-network with a depth head."""
        return add_depth_head(super().make_q_net())


def depth_loss(net: QNetwork, features: th.Tensor, targets: th.Tensor) -> th.Tensor:
    """Return the auxiliary depth loss: the head's mean squared error on the known targets.

    ``targets``: ``(batch, cells)`` metres, NaN where a sample's depth is unknown (an episode's
    first frame, :class:`DepthTargets`); the loss is on depths over ``DEPTH_RANGE`` (0-1).
    """
    known = ~th.isnan(targets).any(dim=1)
    if not bool(known.any()):
        return features.sum() * 0.0
    predicted = net.depth_head(features[known])
    return F.mse_loss(predicted, targets[known] / DEPTH_RANGE)


class DepthTargets:
    """A replay buffer mixin that keeps the coarse depth of each stored observation.

    The depth of the frame a transition starts from is the one ``info['depth']`` gave with the
    step that led to it; an episode's first frame came with its reset, which SB3 does not pass
    to the buffer: the learner gives it (:func:`begin_depths`), and without it the depth stays
    unknown (NaN) and the loss skips it.  ``_get_samples``
    keeps the sampled ones in ``last_depths`` ``(batch, cells)`` float32, found at the same
    (position, env) as the observations: SB3 draws the env of each sample as its first random
    number, which this draws again from the same state.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """Create the buffer and its depth store."""
        super().__init__(*args, **kwargs)
        self.depths = np.full((self.buffer_size, self.n_envs, DEPTH_CELLS), np.nan, np.float32)
        self.pending = np.full((self.n_envs, DEPTH_CELLS), np.nan, np.float32)
        self.last_depths = np.zeros((0, DEPTH_CELLS), np.float32)

    def add(self, obs: Any, next_obs: Any, action: Any, reward: Any, done: Any,
            infos: list[dict[str, Any]]) -> None:
        """Store the transition and its observation's depth; keep the next frame's."""
        self.depths[self.pos] = self.pending
        super().add(obs, next_obs, action, reward, done, infos)
        for env, (info, ended) in enumerate(zip(infos, np.asarray(done).reshape(-1),
                                                strict=True)):
            depth = info.get(DEPTH_KEY)
            self.pending[env] = np.nan if ended or depth is None else np.ravel(depth)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Load a pickled buffer: the frame after its newest one begins an episode (a resume)."""
        self.__dict__.update(state)
        self.pending = np.full_like(self.pending, np.nan)

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> ReplayBufferSamples:
        state = np.random.get_state()
        envs = np.random.randint(0, self.n_envs, size=batch_inds.shape)  # SB3's own draw
        np.random.set_state(state)
        samples = super()._get_samples(batch_inds, env)
        self.last_depths = self.depths[batch_inds, envs]
        return samples


class DepthReplayBuffer(DepthTargets, NStepReplayBuffer):
    """SB3's n-step replay buffer with depth targets."""


class DepthFrameStackReplayBuffer(DepthTargets, FrameStackReplayBuffer):
    """The frame-stack buffer with depth targets (each stack's newest frame's depth)."""


def begin_depths(buffer: Any, venv: Any, envs: Any) -> None:
    """Give the first frame of each of ``envs``' new episodes the depth its reset gave.

    SB3 passes a buffer the infos of steps only; the VecEnv keeps each env's latest reset info
    (``reset_infos``, on the innermost VecEnv: a wrapper has its own).  Nothing for a buffer
    without depth targets.
    """
    if not isinstance(buffer, DepthTargets):
        return
    infos = venv.unwrapped.reset_infos
    for env in envs:
        depth = infos[env].get(DEPTH_KEY)
        if depth is not None:
            buffer.pending[env] = np.ravel(depth)
