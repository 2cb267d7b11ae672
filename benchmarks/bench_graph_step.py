"""A plain PyTorch Double-DQN gradient step on a GPU: eager vs captured as a CUDA graph.

    python benchmarks/bench_graph_step.py [cuda|cpu] [control]

The same network as SB3's CnnPolicy (NatureCNN, 512, 3 actions), batch 32 sampled on the CPU
from a 50,000-transition uint8 buffer, 3-step returns precomputed, Adam, gradient clipping at
10; the graph's batch is copied into static tensors and the whole step (forward passes, loss,
backward pass, clipping, Adam with ``capturable=True``) replayed.  Prints the ms per step of
each (5 alternating rounds of 100 steps) and, after 20 identical steps from the same start, the
largest difference of the loss and of the weights.  ``control`` makes the second learner eager
too: the differences two eager runs already have (cuDNN's algorithms are not deterministic).
Without CUDA both are eager.  Issue 29's probe for the learner's launch overhead on a GPU.
"""
from __future__ import annotations

import copy
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

dev = sys.argv[1] if len(sys.argv) > 1 else 'cuda'
torch.manual_seed(0)


def net() -> nn.Module:
    """Return SB3's CnnPolicy Q-network for (3, 84, 84) images and 3 actions, on the device."""
    return nn.Sequential(nn.Conv2d(3, 32, 8, 4), nn.ReLU(), nn.Conv2d(32, 64, 4, 2), nn.ReLU(),
                         nn.Conv2d(64, 64, 3, 1), nn.ReLU(), nn.Flatten(), nn.Linear(3136, 512),
                         nn.ReLU(), nn.Linear(512, 3)).to(dev)


SIZE, B = 50_000, 32
rng = np.random.default_rng(1)
OBS = np.frombuffer(rng.bytes(SIZE * 3 * 84 * 84), np.uint8).reshape(SIZE, 3, 84, 84)
NEXT = np.frombuffer(rng.bytes(SIZE * 3 * 84 * 84), np.uint8).reshape(SIZE, 3, 84, 84)
ACT = rng.integers(0, 3, SIZE)
RET = rng.normal(size=SIZE).astype(np.float32)
DONE = (rng.random(SIZE) < 0.01).astype(np.float32)
DISC = np.float32(0.99 ** 3)


def sample(r: np.random.Generator) -> tuple[torch.Tensor, ...]:
    """Draw a batch from the buffer (on the CPU, as SB3's replay buffer does)."""
    i = r.integers(0, SIZE, B)
    return (torch.from_numpy(OBS[i]), torch.from_numpy(NEXT[i]),
            torch.from_numpy(ACT[i]).reshape(-1, 1), torch.from_numpy(RET[i]).reshape(-1, 1),
            torch.from_numpy(DONE[i]).reshape(-1, 1))


class Learner:
    """Online and target networks with Adam; its step eager, or replayed as a CUDA graph."""

    def __init__(self, online: nn.Module, graph: bool) -> None:
        """Copy ``online``; with ``graph``, warm up and capture the step, then start afresh."""
        self.online = copy.deepcopy(online)
        self.target = copy.deepcopy(online)
        self.opt = torch.optim.Adam(self.online.parameters(), lr=1e-4, capturable=graph,
                                    foreach=True)
        self.static = [torch.zeros((B, 3, 84, 84), dtype=torch.uint8, device=dev),
                       torch.zeros((B, 3, 84, 84), dtype=torch.uint8, device=dev),
                       torch.zeros((B, 1), dtype=torch.int64, device=dev),
                       torch.zeros((B, 1), device=dev), torch.zeros((B, 1), device=dev)]
        self.graph = None
        if graph:
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            keep = copy.deepcopy(self.online.state_dict())
            with torch.cuda.stream(side):
                for _ in range(3):
                    self.opt.zero_grad(set_to_none=True)
                    self.body()
            torch.cuda.current_stream().wait_stream(side)
            self.graph = torch.cuda.CUDAGraph()
            self.opt.zero_grad(set_to_none=True)
            with torch.cuda.graph(self.graph):
                self.loss = self.body()
            # the warm-up steps changed the weights and Adam's state: start again from keep
            with torch.no_grad():
                for name, p in self.online.named_parameters():
                    p.copy_(keep[name])
            for state in self.opt.state.values():
                for value in state.values():
                    value.zero_()

    def body(self) -> torch.Tensor:
        """One gradient step on the static batch; returns the loss."""
        obs, nxt, act, ret, done = self.static
        o, n = obs.float() / 255.0, nxt.float() / 255.0
        with torch.no_grad():
            nt = self.target(n)
            best = self.online(n).argmax(dim=1, keepdim=True)
            tgt = ret + (1 - done) * DISC * nt.gather(1, best)
        cur = self.online(o).gather(1, act)
        loss = F.smooth_l1_loss(cur, tgt)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.online.parameters(), 10.0)
        self.opt.step()
        return loss

    def step(self, batch: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """Copy ``batch`` into the static tensors and take one step."""
        for s, b in zip(self.static, batch, strict=True):
            s.copy_(b)
        if self.graph is not None:
            self.graph.replay()
            return self.loss
        self.opt.zero_grad(set_to_none=True)
        return self.body()


def sync() -> None:
    """Wait for the GPU's queued work."""
    if dev.startswith('cuda'):
        torch.cuda.synchronize()


base = net()
graph = dev.startswith('cuda') and 'control' not in sys.argv
eager, graphed = Learner(base, False), Learner(base, graph)
# the same update: 20 identical batches from the same start
r1, r2 = np.random.default_rng(5), np.random.default_rng(5)
worst_loss = 0.0
for _ in range(20):
    a, b = eager.step(sample(r1)), graphed.step(sample(r2))
    worst_loss = max(worst_loss, abs(a.item() - b.item()))
worst_w = max((p - q).abs().max().item() for p, q in zip(eager.online.parameters(),
                                                        graphed.online.parameters(), strict=True))
print(f'after 20 identical steps: largest loss difference {worst_loss:.3g}, '
      f'largest weight difference {worst_w:.3g}', flush=True)
times = {'eager': [], 'graph': []}
r = np.random.default_rng(7)
for _ in range(5):
    for name, learner in (('eager', eager), ('graph', graphed)):
        sync()
        start = time.perf_counter()
        for _ in range(100):
            learner.step(sample(r))
        sync()
        times[name].append((time.perf_counter() - start) / 100 * 1e3)
for name, values in times.items():
    rounds = [round(v, 3) for v in values]
    print(f'{name}: {np.median(values):.3f} ms per gradient step (rounds {rounds})', flush=True)
print(f'ratio graph / eager: {np.median(times["graph"]) / np.median(times["eager"]):.2f}')
