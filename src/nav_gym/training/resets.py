"""Periodic resets of the Q-network's fully connected layers (Nikishin et al. 2022).

The primacy bias: a network trained on its first experiences keeps fitting them and learns
less from later ones, the more so at a higher replay ratio.  Resetting the last layers every so
often, while the replay buffer keeps everything, undoes that; with resets a learner can raise
its replay ratio (``gradient_steps`` over ``train_freq``) without the loss.

Here a reset re-initialises every ``nn.Linear`` of the online Q-network (NatureCNN's hidden
layer, the Q head, a dueling value head and an auxiliary head) the way PyTorch initialised
them, keeps the convolutions, and drops the optimiser's state (Adam's moments and step) of the
reset parameters, so they start afresh.  The target network is left to its own schedule: until
its next update it still values the next states as the trained head did.
"""

from __future__ import annotations

import torch as th
from torch import nn


def reset_fully_connected(net: nn.Module, optimizer: th.optim.Optimizer) -> int:
    """Re-initialise every ``nn.Linear`` of ``net`` and forget its optimiser state.

    Draws from torch's global generator.  Returns the number of layers reset.
    """
    layers = [module for module in net.modules() if isinstance(module, nn.Linear)]
    for layer in layers:
        layer.reset_parameters()
        for parameter in layer.parameters():
            optimizer.state.pop(parameter, None)
    return len(layers)
