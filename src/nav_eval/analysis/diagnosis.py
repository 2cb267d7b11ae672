"""Diagnose one failed evaluation episode layer by layer (pure: numpy; no ROS, no plots).

Runs every check of :mod:`nav_eval.analysis.failure_layers` on one episode's trace and frames,
with the run's settings, its training evidence and, when given, the actions of a re-run of the
episode, and names the earliest layer that looks broken or suspect.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.analysis import failure_layers as layers
from nav_gym.env.config import EnvConfig
from nav_gym.policy.servo import servo_band
from nav_gym.training.run_dir import MONITOR, read_monitor, truthy
from nav_sim.core.config import SimConfig


def training_evidence(run_dir: Path, final_eps: float, tail: int = 50) -> dict | None:
    """Episodes and late success rate from the run's Monitor CSV."""
    path = run_dir / MONITOR
    if not path.is_file():
        return None
    success = read_monitor(path).get('is_success', [])
    if not success:
        return None
    last = success[-tail:]
    return {'episodes': len(success), 'tail': len(last),
            'tail_success': sum(map(truthy, last)) / len(last), 'final_eps': final_eps}


def diagnose(trace: dict, frames: np.ndarray, sim: SimConfig, env: EnvConfig,
             training: dict | None = None, eval_config: dict | None = None,
             run_config: dict | None = None,
             rerun_actions: list[int] | None = None) -> dict[str, Any]:
    """Run every layer check; returns the diagnosis (JSON-ready)."""
    steps, scenario = trace['steps'], trace['scenario']
    weights = {k: getattr(env, k) for k in ('progress_weight', 'step_penalty', 'goal_reward',
                                            'collision_penalty')}
    verdicts = [
        layers.check_observations(frames, steps),
        layers.check_actions(steps, scenario['start'], env.forward_speed * sim.ctrl_dt,
                             env.turn_rate * sim.ctrl_dt,
                             layers.arc_chord(env.turn_speed, env.turn_rate, sim.ctrl_dt)),
        layers.check_reward(steps, scenario['initial_distance'], weights),
        layers.check_policy(steps, frames, trace['outcome'], training,
                            servo_band(env.turn_rate, sim.ctrl_dt, sim.camera_hfov_deg)),
        layers.check_evaluation(trace, eval_config, run_config, rerun_actions),
    ]
    earliest = next((v for v in verdicts if v.status in ('broken', 'suspect')), None)
    summary = (f"{trace['set']} seed {trace['seed']} ended in {trace['outcome']} after "
               f"{len(steps)} steps. ")
    if earliest is None:
        summary += 'No layer shows a problem in the evidence available.'
    else:
        summary += (f'Earliest layer that looks {earliest.status}: {earliest.layer} — '
                    f'{earliest.reason}')
    return {'set': trace['set'], 'seed': trace['seed'], 'split': trace['split'],
            'checkpoint': trace.get('checkpoint'), 'outcome': trace['outcome'],
            'earliest_suspect_layer': earliest.layer if earliest else None,
            'layers': [asdict(v) for v in verdicts], 'summary': summary}
