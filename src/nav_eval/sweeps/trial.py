"""One trial of a sweep: the plain commands in a child process, in a ROS domain of its own.

A training trial is one child (``python -m nav_eval.sweep_trial TRIAL_JSON``) that runs
``nav-gym-train`` (or ``--resume`` from the newest checkpoint when the run directory already
holds one) and then evaluates (:mod:`nav_eval.evaluation`) the final model on the sweep's training
and held-out seeds, and every checkpoint on a small held-out set for the sample-efficiency
curve: the same code as the plain commands, in one process so that torch, Stable-Baselines3
and rclpy are imported once.  A baseline trial is ``python -m nav_eval.baselines`` for one
configuration.  Every stage whose output exists is skipped, so a retried or resumed trial
continues where it stopped.  Children run with a
host-locally reserved ``ROS_DOMAIN_ID``, localhost discovery, the trial's CPU count as their
thread count, and die with the process that started them.  No Ray import: the sweep calls
:func:`run_trial` from its Tune trainable.
"""

from __future__ import annotations

import gc
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from nav_eval.errors import TrialFailedError
from nav_eval.evaluation.sets import BASELINE_POLICIES
from nav_eval.seeds import seed_text
from nav_eval.sweeps.domain import reserve_any_domain
from nav_gym.cli import run_command
from nav_gym.training.run_dir import (
    CONFIG,
    EVAL,
    FINAL_MODEL,
    RESULTS,
    SUMMARY,
    checkpoints,
    curve_checkpoints,
    curve_dir,
)
from nav_sim.core.config import SPLITS
from nav_sim.ros.process import child_preexec

LOG_TAIL_LINES = 15
THREAD_VARIABLES = ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS')


def log_tail(path: Path, lines: int = LOG_TAIL_LINES) -> str:
    """Return the last ``lines`` lines of a log file ('' if there is none)."""
    try:
        text = path.read_text(errors='replace')
    except OSError:
        return ''
    return '\n'.join(text.rstrip().splitlines()[-lines:])


def child_environment(base: dict[str, str], cpus: int) -> dict[str, str]:
    """Return ``base`` with the children's thread counts set to the trial's CPUs."""
    env = dict(base)
    for name in THREAD_VARIABLES:
        env[name] = str(max(1, cpus))
    env.setdefault('MUJOCO_GL', 'egl')
    env.pop('RAY_ADDRESS', None)
    return env


def run_child(command: list[str], env: dict[str, str], log: Path, what: str = '') -> None:
    """Run one stage, its output appended to ``log``; raise TrialFailedError if it fails.

    ``what`` names the stage in the error (default: the command).
    """
    with open(log, 'ab') as handle:
        handle.write(f'\n$ {" ".join(command)}\n'.encode())
        handle.flush()
        start = time.monotonic()
        # its own session: signals to the worker's process group do not reach it; it gets a
        # SIGTERM when the worker dies (and then saves a checkpoint and exits)
        process = subprocess.Popen(command, stdout=handle, stderr=subprocess.STDOUT, env=env,
                                   stdin=subprocess.DEVNULL, preexec_fn=child_preexec,
                                   start_new_session=True)
        # if this thread ends early (the trial is stopped), the child gets a SIGTERM from
        # PR_SET_PDEATHSIG, and again as each ancestor ends: it acts on the first only
        # (nav_gym.cli.stop_on_sigterm), so that none cuts the checkpoint it then saves
        code = process.wait()
        handle.write(f'# exit code {code} after {time.monotonic() - start:.1f} s\n'.encode())
    if code != 0:
        stage = what or f"`{' '.join(command[2:4])[:60]}`"
        raise TrialFailedError(f'{stage} exited with code {code}; the end of {log}:\n'
                               f'{log_tail(log)}')


def train_args(trial: dict[str, Any]) -> list[str] | None:
    """Return ``nav-gym-train``'s arguments for a trial (fresh or ``--resume``), None when done."""
    run_dir = Path(trial['run_dir'])
    if (run_dir / FINAL_MODEL).is_file():
        return None
    device = ['--device', 'cuda' if trial['gpus'] > 0 else 'cpu']
    if (run_dir / CONFIG).is_file() and checkpoints(run_dir):
        return ['--resume', str(run_dir)] + device
    if run_dir.exists():  # stopped before its first checkpoint: nothing to resume from
        shutil.rmtree(run_dir)
    return ['--config', trial['config_file'], '--seed', str(trial['seed']), '--runs-dir',
            str(run_dir.parent), '--run-name', run_dir.name] + device


def has_sets(results: Path, names: list[str], seeds: dict[str, list[int]]) -> bool:
    """Tell whether an evaluation's results hold every named set on the expected seeds."""
    try:
        sets = {s['name']: s for s in json.loads(results.read_text())['sets']}
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return all(n in sets and sets[n]['seeds'] == seeds[n] for n in names)


def missing_evaluations(trial: dict[str, Any]) -> list[tuple[str, str | None, Path]]:
    """Return the evaluations still to run as (set names, checkpoint, output folder).

    The final model on the training and held-out seeds, then every curve point on the curve
    seeds (the sample-efficiency curve; :func:`nav_gym.training.run_dir.is_curve_point`).
    """
    run_dir = Path(trial['run_dir'])
    todo: list[tuple[str, str | None, Path]] = []
    final = {'dqn_train': trial['train_seeds'], 'dqn_heldout': trial['heldout_seeds']}
    if not has_sets(run_dir / EVAL / RESULTS, list(final), final):
        todo.append(('dqn_train,dqn_heldout', None, run_dir / EVAL))
    if trial['curve_seeds']:
        for steps, path in curve_checkpoints(run_dir):
            out = curve_dir(run_dir, steps)
            if not has_sets(out / RESULTS, ['early_heldout'],
                            {'early_heldout': trial['curve_seeds']}):
                todo.append(('early_heldout', str(path.relative_to(run_dir)), out))
    return todo


def evaluate_trial(trial: dict[str, Any]) -> None:
    """Run a trial's missing evaluations in this process (one torch import for all of them)."""
    from nav_eval.evaluation.runner import evaluate  # ROS and torch: only in the child
    from nav_eval.evaluation.sets import plan_sets
    run_dir = Path(trial['run_dir'])
    for names, early, out in missing_evaluations(trial):
        seeds = trial['curve_seeds'] if early else trial['heldout_seeds']
        sets = plan_sets(run_dir, names.split(','), tuple(trial['train_seeds']),
                         tuple(seeds), early=early)
        evaluate(run_dir, sets, out, record=trial['record'] and early is None)
        print(f'evaluated {names} ({early or "final model"}) -> {out}', flush=True)


def trial_command(trial: dict[str, Any]) -> list[str] | None:
    """Return the child that trains and evaluates a trial, or None when nothing is left."""
    if trial_finished(trial):
        return None
    return [sys.executable, '-m', 'nav_eval.sweep_trial', json.dumps(trial)]


def train_and_evaluate(trial: dict[str, Any]) -> int:
    """Run a trial's remaining stages in this process; return the exit code (130: stopped).

    Training is ``nav-gym-train``'s own (its parser, its body and its one-line errors; the
    caller handles SIGTERM as Ctrl-C, so a stopped run saves a checkpoint); evaluation follows
    only a finished training.
    """
    args = train_args(trial)
    if args is not None:
        from nav_gym.training.trainer import command_parser, run_training
        print(f"$ nav-gym-train {' '.join(args)}", flush=True)
        start, code = time.monotonic(), 0
        try:
            parsed = command_parser('nav-gym-train').parse_args(args)
            run_command('nav-gym-train', lambda: run_training(parsed))
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
        print(f'# training exited with code {code} after {time.monotonic() - start:.1f} s',
              flush=True)
        if code:
            return code
        # the model and its replay buffer (GBs) are left in a reference cycle (the training
        # callback keeps learn()'s locals): free them before the evaluation
        gc.collect()
    evaluate_trial(trial)
    return 0


def baseline_command(trial: dict[str, Any]) -> list[str] | None:
    """Return the baseline stage of a configuration, or None when its results exist."""
    out = Path(trial['out'])
    names = [f'{p}_{s}' for p in BASELINE_POLICIES for s in SPLITS]
    seeds = {n: trial['train_seeds'] if n.endswith('_train') else trial['heldout_seeds']
             for n in names}
    if has_sets(out, names, seeds):
        return None
    return [sys.executable, '-m', 'nav_eval.baselines', '--config', trial['config_file'],
            '--train-seeds', seed_text(trial['train_seeds']),
            '--heldout-seeds', seed_text(trial['heldout_seeds']), '--out', str(out)]


def trial_finished(trial: dict[str, Any]) -> bool:
    """Tell whether every stage of a trial has its output (nothing would run)."""
    if trial['kind'] == 'baseline':
        return baseline_command(trial) is None
    return ((Path(trial['run_dir']) / FINAL_MODEL).is_file()
            and not missing_evaluations(trial))


def headline(trial: dict[str, Any]) -> dict[str, Any]:
    """Return a finished trial's headline figures (what the progress line and Tune show)."""
    if trial['kind'] == 'baseline':
        sets = json.loads(Path(trial['out']).read_text())['sets']
        return {f"{s['name']}_success": s['summary']['success_rate'] for s in sets}
    run_dir = Path(trial['run_dir'])
    sets = json.loads((run_dir / EVAL / RESULTS).read_text())['sets']
    out: dict[str, Any] = {}
    for s in sets:
        split = s['split']
        out[f'{split}_success'] = s['summary']['success_rate']
        out[f'{split}_collision'] = s['summary']['collision_rate']
    try:
        summary = json.loads((run_dir / SUMMARY).read_text())
        out['train_wall_s'] = summary.get('wall_clock_total_s')
        out['steps_per_s'] = summary.get('steps_per_s')
    except (OSError, ValueError):
        pass
    return out


def run_trial(trial: dict[str, Any], report: Callable[[dict[str, Any]], None],
              node: str = '') -> None:
    """Run every remaining stage of one trial, then ``report`` its headline figures.

    ``node``: the address of the Ray node the trial runs on (in its log and its report).
    """
    log = Path(trial['log'])
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    with reserve_any_domain() as domain:
        env = child_environment(domain.environment(), trial['cpus'])
        with open(log, 'ab') as handle:
            handle.write(f'\n# attempt at {time.strftime("%Y-%m-%d %H:%M:%S")}, '
                         f'ROS_DOMAIN_ID={domain.domain_id}, node {node or "?"}\n'.encode())
        if trial['kind'] == 'baseline':
            command = baseline_command(trial)
            if command is not None:
                Path(trial['out']).parent.mkdir(parents=True, exist_ok=True)
                run_child(command, env, log)
        else:
            command = trial_command(trial)
            if command is not None:
                run_child(command, env, log, f"trial {trial['name']} (training and evaluation)")
        figures = headline(trial)
    report({**figures, 'domain_id': domain.domain_id, 'pid': os.getpid(), 'node': node,
            'trial_wall_s': round(time.monotonic() - start, 1), 'complete': True})
