"""The learner's cost: the default (or a given) learner against SB3's vanilla DQN, side by side.

    .venv/bin/python benchmarks/bench_learner.py [--set KEY=V ...] [--against KEY=V ...]
        [--gradient-steps 200] [--rounds 5] [--train-steps 6000] [--train-repeats 1]
        [--threads N]

0. **The floor**: the plain PyTorch gradient step of the same computation, in the same run:
   SB3's NatureCNN and head (online and target), a batch sampled from a 50,000-transition uint8
   buffer in memory with its n-step returns precomputed, the uint8 -> float conversion, the
   learner's target rule (Double DQN or the max), the Huber loss, Adam, gradient clipping,
   nothing else.  Timed phase by phase (``torch`` runs synchronously on the CPU).  The
   learner's gradient step (part 1) is printed as a ratio to it: the issue-29 target is 1.15.
1. **The gradient step alone** (no ROS): both learners on an env with only the observation and
   action spaces, their replay buffers filled by ``learning_starts`` steps, then rounds of
   ``--gradient-steps`` gradient steps each, alternating (A B A B ...): the median time per
   gradient step and the ratio.  Then one profiled round each says where a gradient step's time
   goes: replay sampling, the augmentation, the forward passes, the backward pass, gradient
   clipping, the optimiser, the rest (cProfile's cumulative times of those calls; profiling
   slows the small calls, so these are shares, not timings).
2. **Whole trainings** (``--train-steps`` > 0): ``nav-gym-train`` with each learner through the
   ROS env and its own sim, alternating for ``--train-repeats`` rounds: training wall-clock,
   steps/s, the env's share, and the per-env-step time budget of its summary.json
   (``transport``: the sim's period and the round trip; ``gradient_step`` and ``predict``: the
   learner).  ``--train-steps 50000`` is the main job's length (the learner issue's cost target:
   the final learner trains 50k steps no slower than vanilla DQN).

``--set KEY=V`` chooses the learner against vanilla DQN (e.g. ``--set augment_shift=4``); the
default is today's default learner.  ``--against KEY=V`` sets learner A on top of
config/workshop.yaml's settings instead (``--against double_q=true --against n_steps=3``: the
default before issue 30's memory).  ``--threads`` is torch's thread count (default: what
training uses, all cores).
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault('OMP_WAIT_POLICY', 'PASSIVE')  # as training sets it (before torch)
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from nav_gym.env.observation import OBS_SHAPE  # noqa: E402
from nav_gym.policy.history import action_planes  # noqa: E402
from nav_gym.training import config as train_config  # noqa: E402
from nav_gym.training.learner import learner_class, learner_kwargs, learner_policy  # noqa: E402
from nav_gym.training.run_dir import SUMMARY  # noqa: E402
from nav_gym.training.spec import LearnerSpec  # noqa: E402
from nav_sim.core.depth import DEPTH_KEY, DEPTH_RANGE, DEPTH_SHAPE  # noqa: E402

#: the workshop's learner, SB3's DQN exactly: learner A, as nav-gym-train --config trains it
WORKSHOP = Path(__file__).resolve().parents[1] / 'config' / 'workshop.yaml'

#: where a gradient step's time goes: a name -> the calls whose cumulative time it is
PHASES = {'sampling': ('buffers.py', 'sample'),
          'uint8 -> float': ('preprocessing.py', 'preprocess_obs'),
          'random shifts': ('augment.py', 'random_shift'),
          'colour jitter': ('augment.py', 'random_colour'),
          'forward passes': ('module.py', '_call_impl'),
          'backward pass': ('_tensor.py', 'backward'),
          'gradient clipping': ('clip_grad.py', 'clip_grad_norm_'),
          'optimiser': ('optimizer.py', 'wrapper'),
          'logging': ('logger.py', 'record')}
FLOOR_PHASES = ('sampling', 'uint8 -> float', 'forward passes', 'backward pass',
                'gradient clipping', 'optimiser')
FLOOR_BUFFER = 50_000


class SpacesOnly(gym.Env):
    """The env's observation and action spaces with random images: the learner's work only."""

    observation_space = gym.spaces.Box(0, 255, OBS_SHAPE, np.uint8)
    action_space = gym.spaces.Discrete(3)

    def __init__(self) -> None:
        """Draw images (and depths, for ``aux_depth``) from seeded generators; episodes of 100."""
        self.rng, self.t = np.random.default_rng(0), 0
        self.depth_rng = np.random.default_rng(1)

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[np.ndarray, dict]:
        """Start an episode."""
        super().reset(seed=seed)
        self.t = 0
        return self.rng.integers(0, 256, OBS_SHAPE, dtype=np.uint8), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Return a random image; end the episode after 100 steps."""
        self.t += 1
        depth = self.depth_rng.uniform(0.05, DEPTH_RANGE, DEPTH_SHAPE).astype(np.float32)
        return (self.rng.integers(0, 256, OBS_SHAPE, dtype=np.uint8), 0.0, False,
                self.t >= 100, {DEPTH_KEY: depth})


def build(config: train_config.TrainConfig) -> Any:
    """Build the config's learner on the spaces-only env and fill its replay buffer.

    A learner with memory gets the agent's stacks (``FrameStackEnv``), as in training.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv

    from nav_gym.training.memory import agent_envs
    learner = config.learner()
    env = agent_envs(DummyVecEnv([SpacesOnly]), learner)
    model = learner_class(None, learner)(
        learner_policy(learner), env,
        **{**config.dqn_kwargs(), 'buffer_size': 10_000, 'device': 'cpu'},
        **learner_kwargs(learner, config.gamma))
    model.learn(config.learning_starts + 1)
    return model


def time_steps(model: Any, steps: int, batch_size: int) -> float:
    """Return the wall-clock ms per gradient step of ``steps`` gradient steps."""
    start = time.perf_counter()
    model.train(steps, batch_size)
    return (time.perf_counter() - start) / steps * 1e3


def breakdown(model: Any, steps: int, batch_size: int) -> dict[str, float]:
    """Return each phase's share of a profiled round of gradient steps."""
    profile = cProfile.Profile()
    profile.runcall(model.train, steps, batch_size)
    stats = pstats.Stats(profile).stats
    total = max((s[3] for (f, _, name), s in stats.items() if name == 'train'
                 and f.endswith(('dqn.py', 'learner.py'))), default=0.0)
    shares = {}
    for phase, (file, function) in PHASES.items():
        seconds = sum(s[3] for (f, _, name), s in stats.items()
                      if name == function and f.endswith(file))
        if phase == 'forward passes':  # the outermost module calls only (cumtime counts once)
            seconds = max(seconds, 0.0)
        shares[phase] = seconds / total if total else 0.0
    shares['the rest'] = max(0.0, 1.0 - sum(shares.values()))
    return shares


class Floor:
    """The plain PyTorch gradient step of the learner's computation (part 0)."""

    def __init__(self, config: train_config.TrainConfig, model: Any) -> None:
        """Copy the learner's networks; fill a 50,000-transition uint8 buffer at random."""
        import copy
        self.config, self.learner = config, config.learner()
        self.online = copy.deepcopy(model.q_net).float()
        self.target = copy.deepcopy(model.q_net_target).float()
        self.optimizer = torch.optim.Adam(self.online.parameters(), lr=config.learning_rate)
        self.max_grad_norm = model.max_grad_norm
        assert not self.learner.dueling, 'the floor is the plain head (no dueling)'
        rng = np.random.default_rng(1)
        shape = (FLOOR_BUFFER, *OBS_SHAPE)
        self.obs = np.frombuffer(rng.bytes(int(np.prod(shape))), np.uint8).reshape(shape)
        self.next_obs = np.frombuffer(rng.bytes(int(np.prod(shape))), np.uint8).reshape(shape)
        self.actions = rng.integers(0, 3, FLOOR_BUFFER)
        # a learner with memory: its stacks composed from the single frames at sampling time
        self.k = self.learner.frame_stack
        self.planes = 3 if self.learner.previous_action else 0
        n = self.learner.n_steps  # n-step returns and their discounts, precomputed
        self.returns = rng.normal(size=FLOOR_BUFFER).astype(np.float32)
        self.discounts = np.full(FLOOR_BUFFER, config.gamma ** n, np.float32)
        self.dones = (rng.random(FLOOR_BUFFER) < 0.01).astype(np.float32)
        # aux_depth: each observation's coarse depth, the head's target beside it
        self.depths = rng.uniform(0.05, DEPTH_RANGE, (FLOOR_BUFFER, int(np.prod(DEPTH_SHAPE)))
                                  ).astype(np.float32)
        self.rng = rng

    def step(self, batch: int, seconds: dict[str, float]) -> None:
        """One gradient step, adding each phase's time to ``seconds``."""
        clock = time.perf_counter
        t0 = clock()
        index = self.rng.integers(0, FLOOR_BUFFER, batch)
        obs = torch.from_numpy(self.stacks(self.obs, index, self.actions[index - 1]))
        next_obs = torch.from_numpy(self.stacks(self.next_obs, index, self.actions[index]))
        actions = torch.from_numpy(self.actions[index]).reshape(-1, 1)
        returns = torch.from_numpy(self.returns[index]).reshape(-1, 1)
        discounts = torch.from_numpy(self.discounts[index]).reshape(-1, 1)
        dones = torch.from_numpy(self.dones[index]).reshape(-1, 1)
        t1 = clock()
        obs, next_obs = obs.float() / 255.0, next_obs.float() / 255.0
        t2 = clock()
        with torch.no_grad():
            next_target = self.target.q_net(self.target.features_extractor(next_obs))
            if self.learner.double_q:
                best = self.online.q_net(self.online.features_extractor(next_obs)).argmax(
                    dim=1, keepdim=True)
                next_q = next_target.gather(1, best)
            else:
                next_q = next_target.max(dim=1, keepdim=True).values
            target = returns + (1.0 - dones) * discounts * next_q
        features = self.online.features_extractor(obs)
        current = self.online.q_net(features).gather(1, actions)
        loss = torch.nn.functional.smooth_l1_loss(current, target)
        if self.learner.aux_depth:
            depths = torch.from_numpy(self.depths[index]) / DEPTH_RANGE
            loss = loss + self.learner.aux_depth * torch.nn.functional.mse_loss(
                self.online.depth_head(features), depths)
        t3 = clock()
        self.optimizer.zero_grad()
        loss.backward()
        t4 = clock()
        torch.nn.utils.clip_grad_norm_(self.online.parameters(), self.max_grad_norm)
        t5 = clock()
        self.optimizer.step()
        t6 = clock()
        for phase, span in zip(FLOOR_PHASES, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4,
                                              t6 - t5), strict=True):
            seconds[phase] += span

    def stacks(self, frames: np.ndarray, index: np.ndarray, before: np.ndarray) -> np.ndarray:
        """Return the observations at ``index``: the frame, or its stack and action planes."""
        if self.k == 1 and not self.planes:
            return frames[index]
        parts = [frames[(index - j) % FLOOR_BUFFER] for j in range(self.k - 1, -1, -1)]
        if self.planes:
            parts.append(action_planes(before, self.planes, OBS_SHAPE[1:]))
        return np.concatenate(parts, axis=1)

    def time_steps(self, steps: int, batch: int, seconds: dict[str, float]) -> float:
        """Return the wall-clock ms per step of ``steps`` floor steps."""
        start = time.perf_counter()
        for _ in range(steps):
            self.step(batch, seconds)
        return (time.perf_counter() - start) / steps * 1e3


def gradient_steps(configs: dict[str, Any], steps: int, rounds: int) -> None:
    """Parts 0 and 1: alternate the floor's and the learners' rounds; print the ratios."""
    models = {name: build(config) for name, config in configs.items()}
    floor = Floor(configs['B'], models['B'])
    floor_seconds = dict.fromkeys(FLOOR_PHASES, 0.0)
    times: dict[str, list[float]] = {name: [] for name in [*models, 'floor']}
    for _ in range(rounds):
        for name, model in models.items():
            times[name].append(time_steps(model, steps, configs[name].batch_size))
        times['floor'].append(floor.time_steps(steps, configs['B'].batch_size, floor_seconds))
    floor_ms = statistics.median(times['floor'])
    total = sum(floor_seconds.values())
    print(f'\n0. the floor: plain PyTorch, the same step as B (batch {configs["B"].batch_size}, '
          f'{torch.get_num_threads()} torch threads): median {floor_ms:6.2f} ms')
    print('   ' + ', '.join(f'{phase} {floor_seconds[phase] / total:.1%}'
                          for phase in FLOOR_PHASES))
    ratios_b = [a / b for a, b in zip(times['B'], times['floor'], strict=True)]
    ratios_a = [a / b for a, b in zip(times['A'], times['floor'], strict=True)]
    print(f'   B / floor: median {statistics.median(ratios_b):.3f} (target <= 1.15); '
          f'A / floor: median {statistics.median(ratios_a):.3f}')
    names = list(models)
    print(f'\n1. one gradient step (batch {configs[names[0]].batch_size}, '
          f'{torch.get_num_threads()} torch threads, {rounds} alternating rounds of {steps})')
    for name in names:
        print(f'   {name}: median {statistics.median(times[name]):6.2f} ms '
              f'(min {min(times[name]):.2f}, max {max(times[name]):.2f})')
    ratios = [a / b for a, b in zip(times[names[1]], times[names[0]], strict=True)]
    print(f'   ratio {names[1]} / {names[0]}: median {statistics.median(ratios):.3f} '
          f'(min {min(ratios):.3f}, max {max(ratios):.3f})')
    print('   where the time goes (profiled round, shares of the gradient step):')
    shares = {name: breakdown(model, steps, configs[name].batch_size)
              for name, model in models.items()}
    print('   ' + f"{'phase':<20}" + ''.join(f'{n:>8}' for n in names))
    for phase in [*PHASES, 'the rest']:
        print('   ' + f'{phase:<20}' + ''.join(f'{shares[n][phase]:>8.1%}' for n in names))


def train_once(settings: list[str], steps: int, folder: Path, name: str) -> dict[str, Any]:
    """Run ``nav-gym-train`` for ``steps`` steps with ``--KEY V`` settings; return its summary."""
    flags = [a for s in settings for a in ('--' + s.split('=')[0].replace('_', '-'),
                                           s.split('=', 1)[1])]
    command = [sys.executable, '-m', 'nav_gym.train', '--total-timesteps', str(steps),
               '--runs-dir', str(folder), '--run-name', name, '--save-replay-buffer', 'false',
               '--checkpoint-freq', str(steps), *flags]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, timeout=steps * 0.2 + 600)
    return json.loads((folder / name / SUMMARY).read_text())


def trainings(settings: dict[str, list[str]], steps: int, repeats: int) -> None:
    """Part 2: whole trainings through the ROS env, alternating; print times and the budget."""
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in settings}
    with tempfile.TemporaryDirectory(prefix='bench_learner_') as tmp:
        for round_ in range(repeats):
            for index, (name, flags) in enumerate(settings.items()):
                runs[name].append(train_once(flags, steps, Path(tmp), f'r{round_}_{index}'))
    names = list(runs)
    print(f'\n2. whole trainings of {steps:,} steps through the ROS env ({repeats} alternating '
          'rounds; per env step, ms)')
    for name in names:
        walls = [r['wall_clock_s'] for r in runs[name]]
        budget = runs[name][-1]['time_budget']['env_step']
        phases = ', '.join(f"{k.removesuffix('_ms')} {v:.2f}" for k, v in budget.items()
                           if k.endswith('_ms') and v)
        print(f'   {name}: wall-clock median {statistics.median(walls):7.1f} s, '
              f"{runs[name][-1]['steps_per_s']:.1f} steps/s, env share "
              f"{runs[name][-1]['env_share']:.1%}; {phases}")
    ratios = [a['wall_clock_s'] / b['wall_clock_s']
              for a, b in zip(runs[names[1]], runs[names[0]], strict=True)]
    print(f'   ratio {names[1]} / {names[0]} (wall-clock): median {statistics.median(ratios):.3f}'
          f' (min {min(ratios):.3f}, max {max(ratios):.3f})')


def main() -> None:
    """Measure vanilla DQN (or the learner ``--against`` names) and the chosen one side by side."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--set', action='append', default=[], metavar='KEY=V',
                        help='a learner setting of the compared learner (nav-gym-train --help)')
    parser.add_argument('--against', action='append', default=[], metavar='KEY=V',
                        help="a learner setting of A on top of config/workshop.yaml's (e.g. "
                             'double_q=true and n_steps=3: the default before issue 30)')
    parser.add_argument('--gradient-steps', type=int, default=200)
    parser.add_argument('--rounds', type=int, default=5)
    parser.add_argument('--train-steps', type=int, default=6000, help='0: skip part 2')
    parser.add_argument('--train-repeats', type=int, default=1)
    parser.add_argument('--threads', type=int, default=0, help='torch threads (0: default)')
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    workshop = train_config.load_yaml(WORKSHOP)  # SB3's DQN: every learner setting of A
    learner_keys = {f.name for f in dataclasses.fields(LearnerSpec)} | set(workshop)
    common = [s for s in args.set if s.split('=')[0] not in learner_keys]  # both learners'
    vanilla = [f'{k}={str(v).lower()}' for k, v in workshop.items()]
    flags = {'A': [*common, *vanilla, *args.against], 'B': args.set}
    configs = {name: train_config.build(None, dict(s.split('=', 1) for s in settings))
               for name, settings in flags.items()}
    baseline = configs['A'].learner()
    assert args.against or baseline.vanilla
    print(f"A: {baseline.describe() if args.against else 'vanilla DQN (SB3)'}\n"
          f"B: {configs['B'].learner().describe()}")
    gradient_steps(configs, args.gradient_steps, args.rounds)
    if args.train_steps:
        trainings(flags, args.train_steps, args.train_repeats)


if __name__ == '__main__':
    main()
