"""The recurrent Q-network (``recurrent``): an LSTM over the CNN features of the agent's window.

Issue 30's third kind of memory (DRQN, Hausknecht & Stone 2015; R2D2's burn-in, Kapturowski et
al. 2019), built as a features extractor of SB3's Q-network so that everything else is SB3's
and the frame stack's: the agent's window of its last ``frame_stack`` frames
(:class:`nav_gym.policy.history.FrameHistory`, the one history rule) is the network's input,
replayed from single frames (:class:`nav_gym.training.memory.FrameStackReplayBuffer`).

Each frame of the window goes through its own pass of SB3's ``NatureCNN`` (shared weights), an
LSTM reads the frames' features oldest first from a zero state, and its last output is the
features of SB3's Q head, one linear layer as NatureCNN's (with the previous action's one-hot
values after it, ``previous_action``).
So the state always begins at the window's oldest frame: the ``k - 1`` frames before the latest
are the burn-in that builds the state, the loss is on the latest, and a window never crosses an
episode's start (the episode's first frame stands in before it, as the stack pads).  Unlike
R2D2's burn-in, these frames are not detached: with the loss on one step, backpropagation
through the whole window is what teaches the LSTM what to keep, and with a zero start state
there is no stored, stale state for a gradient-free burn-in to refresh.  Acting
builds the same window and runs the same pass: training, lockstep and closed-loop evaluation,
the policy node and the ONNX export share one definition of the memory, and no recurrent
state is carried between decisions.  What this leaves out, against R2D2: a state carried over
the whole episode, which needs stored states and a state input in every actor.

``reset_interval`` re-initialises the CNN's linear layer and the heads, not the LSTM.
"""

from __future__ import annotations

import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, NatureCNN
from torch import nn

from nav_gym.env.observation import OBS_SHAPE
from nav_gym.training.memory import frame_space

CNN_FEATURES = 512  # NatureCNN's default: each frame's features, the LSTM's input


class RecurrentCnn(BaseFeaturesExtractor):
    """NatureCNN on every frame of a ``frames``-frame window, then an LSTM of ``hidden`` units.

    The input is a window as :func:`nav_gym.training.memory.stacked_space` lays it out (frames
    of the env's ``OBS_SHAPE`` oldest first along the channels, then the action planes, if
    any: the channels left over), scaled to 0-1 by SB3; the features are the LSTM's output at
    the latest frame, then the previous action's one-hot values (the planes' first pixel).
    """

    def __init__(self, observation_space: spaces.Box, frames: int, hidden: int,
                 previous_action: bool = False) -> None:
        """Build the per-frame CNN and the LSTM for windows of ``observation_space``."""
        if frames < 2:
            raise ValueError(f'a recurrent network reads a window of at least 2 frames, '
                             f'got {frames}')
        n_actions = observation_space.shape[0] - frames * OBS_SHAPE[0]
        if n_actions < 0 or (n_actions > 0) != previous_action:
            raise ValueError(f'{observation_space.shape} is not a window of {frames} frames'
                             f"{' and action planes' if previous_action else ''}")
        super().__init__(observation_space, hidden + n_actions)
        self.frames, self.n_actions = frames, n_actions
        one = frame_space(observation_space, frames, n_actions)
        self.frame_shape = one.shape
        self.cnn = NatureCNN(one, features_dim=CNN_FEATURES, normalized_image=False)
        self.lstm = nn.LSTM(CNN_FEATURES, hidden, batch_first=True)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        """Return the LSTM's output at each window's latest frame (and the action values)."""
        batch = observations.shape[0]
        channels = self.frames * self.frame_shape[0]
        frames = observations[:, :channels].reshape(batch * self.frames, *self.frame_shape)
        features = self.cnn(frames).reshape(batch, self.frames, CNN_FEATURES)
        outputs, _ = self.lstm(features)  # from a zero state at the window's oldest frame
        latest = outputs[:, -1]
        if not self.n_actions:
            return latest
        return th.cat([latest, observations[:, channels:, 0, 0]], dim=1)


def recurrent_policy_kwargs(frames: int, hidden: int, previous_action: bool) -> dict:
    """Return the ``policy_kwargs`` that give SB3's Q-networks the recurrent extractor.

    ``net_arch`` is empty, so that the Q head is one linear layer on the features, as SB3
    gives NatureCNN (for any other extractor it would add two hidden layers of 64).
    """
    return {'features_extractor_class': RecurrentCnn,
            'features_extractor_kwargs': {'frames': frames, 'hidden': hidden,
                                          'previous_action': previous_action},
            'net_arch': []}
