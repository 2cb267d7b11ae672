"""Baselines on both scenario banks: how hard each bank is without any learning.

The uniform-random policy, the image-only servo and the privileged oracle (the ceiling: a plan
on the true map driven with the same actions; :mod:`nav_eval.evaluation.policies`) run on the
training and the held-out seeds through the same environment a run trains on (its sim
settings, action speeds and episode limit).  The result has the shape of an evaluation's
``results.json`` (one entry per set with its summary and episodes), so the sweep's statistics
read both alike.
"""

from __future__ import annotations

from typing import Any

from nav_eval.analysis import metrics
from nav_eval.errors import EvaluationError
from nav_eval.evaluation.policies import OraclePolicy, RandomPolicy, ServoPolicy
from nav_eval.evaluation.runner import env_for_run, run_episode
from nav_eval.evaluation.sets import BASELINE_POLICIES
from nav_gym.policy.actors import Actor
from nav_gym.training.config import TrainConfig
from nav_sim.core.config import HELDOUT, SPLITS, TRAIN, SimConfig


def make_policy(name: str, config: TrainConfig) -> Actor:
    """Make the baseline policy ``name`` for the actions and camera of ``config``."""
    if name == 'random':
        return RandomPolicy()
    if name == 'servo':
        sim = SimConfig.from_params(config.sim_params)
        return ServoPolicy.for_actions(config.turn_rate, sim.ctrl_dt, sim.camera_hfov_deg)
    if name == 'oracle':
        return OraclePolicy(config)
    raise EvaluationError(f'unknown baseline policy {name!r}; known: {BASELINE_POLICIES}')


def run_baselines(config: TrainConfig, train_seeds: tuple[int, ...],
                  heldout_seeds: tuple[int, ...],
                  policies: tuple[str, ...] = BASELINE_POLICIES,
                  progress: bool = False) -> dict[str, Any]:
    """Run every baseline policy on both banks; returns ``{'config': ..., 'sets': [...]}``."""
    seeds = {TRAIN: train_seeds, HELDOUT: heldout_seeds}
    env = env_for_run(config, record=False)
    sets = []
    try:
        for name in policies:
            policy = make_policy(name, config)
            for split in SPLITS:
                results = [run_episode(env, policy, seed, split)[0] for seed in seeds[split]]
                summary = metrics.summarize(results)
                if progress:
                    print(f'  {name:<6} {split:<7} {len(results)} episodes: success '
                          f'{summary.success_rate:.0%}, collisions {summary.collision_rate:.0%}',
                          flush=True)
                sets.append({'name': f'{name}_{split}', 'policy': name, 'split': split,
                             'seeds': list(seeds[split]), 'summary': summary.to_dict(),
                             'episodes': [r.to_dict() for r in results]})
    finally:
        env.close()
    return {'config': {'sim_params': config.sim_params, 'forward_speed': config.forward_speed,
                       'turn_rate': config.turn_rate, 'turn_speed': config.turn_speed,
                       'max_episode_steps': config.max_episode_steps},
            'sets': sets}
