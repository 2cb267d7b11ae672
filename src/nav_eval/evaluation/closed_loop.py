"""Closed-loop evaluation in real time: the policy node drives a realtime sim; nobody waits.

For each realtime rate R the sim node runs in ``realtime`` mode at ``realtime_rate`` R (1 = wall
clock) and the policy node (``ros2 run nav_gym policy``) with the run's model decides every
``ctrl_dt / R`` wall-clock seconds from the newest image, each in its own process.  Each seed
starts with the sim's ``reset`` service and ends at the episode's ``goal``/``collision`` event
or after ``max_episode_steps`` control periods (the time limit, as in lockstep).  The policy
keeps deciding between episodes; the reset stops the motors, so no command of the previous
episode acts in the next unless it is published after the reset.

What it writes is what the lockstep evaluation writes (:mod:`nav_eval.evaluation.runner`):
``results.json`` (one set ``rt<R>_<split>`` per rate, plus the lockstep set ``dqn_<split>`` on
the same seeds), ``results.md``, ``episodes.csv``, per-episode traces and frames, and one MCAP
bag per set (with the policy's decisions); under ``RUN/eval_closed_loop`` by default.  A
closed-loop trace step is one control period: the action the sim applied (-1, ``stop``: no
command in effect), the decision's image stamp and the reward terms recomputed from the
period's distance (:func:`nav_gym.env.reward.reward_terms`).  Each closed-loop set also holds the
decision-latency distribution and the checks of the reconstruction
(:mod:`nav_eval.analysis.closed_loop`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.analysis import metrics
from nav_eval.analysis.closed_loop import (
    ImageLatencies,
    commands_in_effect,
    image_latencies,
    latency_summary,
)
from nav_eval.errors import EvaluationError
from nav_eval.evaluation.realtime import Period, RealtimeGraph
from nav_eval.evaluation.runner import (
    env_for_run,
    evaluate_set,
    open_recorder,
    output_dir,
    set_entry,
    write_episode,
    write_results,
)
from nav_eval.evaluation.sets import SET_LABELS, EvalSet, run_config
from nav_gym.env.actions import ACTION_NAMES
from nav_gym.env.config import EnvConfig
from nav_gym.env.observation import image_msg_to_observation
from nav_gym.env.reward import reward_terms
from nav_gym.policy.process import PolicyProcess
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import BAGS, CLOSED_LOOP, FINAL_MODEL
from nav_sim import interface
from nav_sim.core.config import HELDOUT, TRAIN, SimConfig
from nav_sim.core.events import TERMINAL_EVENTS
from nav_sim.errors import VisnavError, describe_exception
from nav_sim.ros.process import SimProcess

DEFAULT_RATES = (1.0, 4.0)
START_TIMEOUT_S = 60.0   # for the sim and the policy node (torch) to start on a busy machine
STOP_NAME = 'stop'       # the action name of a period with no command in effect


@dataclass(frozen=True)
class LoopSettings:
    """How one closed-loop set runs: the rate and what follows from it."""

    rate: float
    ctrl_dt: float
    max_steps: int

    @classmethod
    def of(cls, config: TrainConfig, rate: float) -> LoopSettings:
        """Return the settings of a run's sim and episode limit at ``rate``."""
        return cls(rate, SimConfig.from_params(config.sim_params).ctrl_dt,
                   config.max_episode_steps)

    @property
    def period(self) -> float:
        """Return the policy's decision period in wall-clock seconds (one sim control period)."""
        return self.ctrl_dt / self.rate

    @property
    def timeout(self) -> float:
        """Return the policy's image_timeout and the sim's cmd_vel_timeout: two periods."""
        return 2.0 * self.period

    @property
    def wait(self) -> float:
        """Return how long a period may take to arrive before the sim counts as stuck."""
        return 5.0 * self.period + 5.0


def set_name(rate: float, split: str) -> str:
    """Return the name of a closed-loop set (``rt4_heldout``: rate 4, held-out seeds)."""
    return f'rt{rate:g}_{split}'


def closed_loop_set(rate: float, split: str, seeds: tuple[int, ...],
                    checkpoint: str = FINAL_MODEL) -> EvalSet:
    """Return the closed-loop set of the final model at ``rate`` on ``seeds``."""
    which = 'held-out' if split == HELDOUT else 'training'
    return EvalSet(set_name(rate, split), f'DQN final, closed loop at {rate:g}x real time, '
                   f'{which} seeds', 'dqn', checkpoint, split, seeds)


def start_delay(seed: int, loop: LoopSettings) -> float:
    """Return the wait before an episode's reset: its phase against the policy's timer.

    The reset restarts the sim's period timer; the policy's timer runs on.  Without a wait the
    phase between them would drift only by the reset's own delay from episode to episode, and
    every episode would see about the first one's latency.  A wait drawn uniformly from one
    decision period (seeded by the scenario seed) samples every phase.
    """
    return float(np.random.default_rng([29, seed]).uniform(0.0, loop.period))


def run_episode(graph: RealtimeGraph, seed: int, split: str, env: EnvConfig,
                loop: LoopSettings, observers: list[Any]
                ) -> tuple[Any, dict, np.ndarray, ImageLatencies]:
    """Play one seed in real time; returns its result, trace, frames and latency records."""
    delay = start_delay(seed, loop)
    graph.spin_until(lambda: False, delay)  # take messages meanwhile: none piles up
    scenario, first = graph.reset(seed, split, loop.wait)
    obs, rgb = image_msg_to_observation(first.image)
    event = first.tick.event
    info = {'scenario': scenario, 'seed': seed, 'split': split, 'pose': _pose(event),
            'distance': float(event['distance']), 'goal': tuple(scenario['goal']),
            'episode': event['episode']}
    for observer in observers:
        observer.on_reset(first.tick.stamp_ns, rgb, obs, info)
    frames, steps, periods, commands = [obs], [], [first], []
    previous, total, terminated, truncated = float(event['distance']), 0.0, False, False
    checks = {'periods_missed': 0, 'races': 0, 'twist_mismatches': 0, 'stopped_periods': 0,
              'previous_episode_commands': 0}
    while not (terminated or truncated):
        period = graph.next_period(periods[-1].tick.stamp_ns, loop.wait)
        event = period.tick.event
        if event['episode'] != info['episode']:
            raise EvaluationError('the sim started another episode under the closed-loop '
                                  f'evaluation: is a second client using {graph.client.where}?')
        checks['periods_missed'] += int(event['episode_step']) - len(periods)
        periods.append(period)
        decision = _command(graph, period, first, loop, checks)
        commands.append(decision)
        distance, name = float(event['distance']), str(event['event'])
        terms = reward_terms(previous, distance, name, env)
        previous, reward = distance, float(sum(terms.values()))
        total += reward
        terminated = name in TERMINAL_EVENTS
        truncated = not terminated and int(event['episode_step']) >= loop.max_steps
        obs, rgb = image_msg_to_observation(period.image)
        frames.append(obs)
        step = _step(period, decision, reward, terms)
        action = step['action']
        steps.append(step)
        step_info = {**step, 'pose': _pose(event), 'reward_terms': terms}
        for observer in observers:
            observer.note_q_values(step['q_values'])
            observer.on_step(period.tick.stamp_ns, rgb, obs, action, reward, step_info,
                             terminated or truncated)
    graph.stop()
    result = metrics.episode_result(seed, split, name, truncated, len(steps), total,
                                    scenario['initial_distance'], distance,
                                    float(event['path_length']))
    trace = {'seed': seed, 'split': split, 'outcome': result.outcome, 'realtime_rate': loop.rate,
             'start_delay_s': round(delay, 6),
             'scenario': {k: v for k, v in scenario.items()
                          if k not in ('episode', 'period', 'stamp_ns')},
             'checks': checks, 'steps': steps}
    images = {p.tick.stamp_ns: p.image_published_ns for p in periods[:-1]}
    latency = image_latencies(first.tick, [p.tick for p in periods[1:]], commands,
                              graph.decisions, images)
    return result, trace, np.stack(frames), latency


def _pose(event: dict[str, Any]) -> tuple[float, float, float]:
    return float(event['x']), float(event['y']), float(event['yaw'])


def _command(graph: RealtimeGraph, period: Period, first: Period, loop: LoopSettings,
             checks: dict[str, int]) -> Any:
    """Return the decision in effect in ``period`` (None: a standstill); count the checks."""
    (decision,), races, mismatches = commands_in_effect(
        [period.tick], graph.decisions, first.tick.published_ns, round(loop.timeout * 1e9))
    checks['races'] += races
    checks['twist_mismatches'] += mismatches
    checks['stopped_periods'] += decision is None or decision.action < 0
    # a command decided on an image of the episode before (a stop, such as the policy's 'new
    # episode' one while it waits for the episode's first image, drives nothing)
    stamp = None if decision is None or decision.action < 0 else decision.image_stamp_ns
    checks['previous_episode_commands'] += stamp is not None and stamp < first.tick.stamp_ns
    return decision


def _step(period: Period, decision: Any, reward: float, terms: dict[str, float]
          ) -> dict[str, Any]:
    """Return a period's trace step: the command the sim applied and what followed."""
    event = period.tick.event
    action = -1 if decision is None else decision.action
    return {'step': int(event['episode_step']), 'action': action,
            'action_name': ACTION_NAMES[action] if action >= 0 else STOP_NAME,
            'reward': round(reward, 6), 'reward_terms': {k: round(v, 6) for k, v in terms.items()},
            'distance': round(float(event['distance']), 6),
            'pose': [round(v, 6) for v in _pose(event)], 'event': str(event['event']),
            'q_values': None if decision is None else decision.q_values,
            'stamp_ns': period.tick.stamp_ns,
            'decision_image_stamp_ns': None if decision is None else decision.image_stamp_ns}


class ClosedLoop:
    """A realtime sim and the policy node at one rate, with the graph that follows them."""

    def __init__(self, config: TrainConfig, policy: dict[str, Any], loop: LoopSettings,
                 sim_params: dict[str, Any] | None = None) -> None:
        """Start the sim and the policy node (each its own process) in a fresh namespace.

        ``config``: the run's settings (the sim's); ``policy``: the policy node's ``model``
        and ``policy`` parameters; ``sim_params``: more sim parameters (e.g. ``live_port``).
        """
        self.namespace = f'/visnav_closed_loop_{os.getpid()}_{loop.rate:g}'.replace('.', '_')
        params = {**config.sim_params, 'mode': 'realtime', 'realtime_rate': loop.rate,
                  'publish_clock': True, 'cmd_vel_timeout': loop.timeout, **(sim_params or {})}
        if config.cmd_vel_stamped:  # the sim and the policy node take the run's setting
            params['cmd_vel_stamped'] = policy['cmd_vel_stamped'] = True
        self.sim = SimProcess(self.namespace, params=params)
        self.policy: PolicyProcess | None = None
        self.graph: RealtimeGraph | None = None
        try:
            self.policy = PolicyProcess(self.namespace, {
                **policy, 'period': loop.period, 'image_timeout': loop.timeout,
                'use_sim_time': True})
            self.graph = RealtimeGraph(self.namespace, timeout=max(config.sim_timeout, 10.0))
            self.graph.wait_ready(START_TIMEOUT_S, self.failure)
        except BaseException:
            self.close()
            raise

    def failure(self) -> str | None:
        """Return why the sim or the policy node exited, or None while both run."""
        return self.sim.failure() or (self.policy.failure() if self.policy else None)

    @contextlib.contextmanager
    def dead_named(self) -> Iterator[None]:
        """Say that a process of the loop exited, when it did, instead of a time-out.

        A killed sim shows as silence (no period, a service that does not answer); within this
        block, an error while the sim or the policy node has exited names the process, its exit
        code or signal.
        """
        try:
            yield
        except VisnavError as exc:
            died = self.failure()
            if died is None:
                raise
            raise EvaluationError(f'{died} (while {describe_exception(exc)})') from exc

    def close(self) -> None:
        """Stop the graph, the policy node (its zero Twist) and the sim."""
        if self.graph is not None:
            self.graph.close()
        if self.policy is not None:
            self.policy.stop()
        self.sim.stop()

    def __enter__(self) -> ClosedLoop:
        """Use as a context manager that stops both processes."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop the graph and both processes."""
        self.close()


def evaluate_rate(run_dir: Path, config: TrainConfig, eval_set: EvalSet, rate: float,
                  out: Path, record: bool, live: Any = None) -> dict[str, Any]:
    """Run one closed-loop set; write its traces (and bag); return its results entry."""
    loop = LoopSettings.of(config, rate)
    env = config.env_config()
    print(f'closed loop at {rate:g}x real time: decisions every {loop.period:.3f} s '
          f'(wall clock), {len(eval_set.seeds)} episodes', flush=True)
    loop_graph = ClosedLoop(config, {'model': str(run_dir / str(eval_set.checkpoint))}, loop)
    graph = loop_graph.graph
    assert graph is not None
    if live is not None:
        graph.forward = live.forward
    observers: list[Any] = [] if live is None else [live]
    recorder = None
    try:
        if record:
            from nav_eval.recording.scene import BagSceneWriter
            from nav_eval.recording.topics import WITH_POLICY
            recorder = open_recorder(
                out / BAGS / eval_set.name, loop_graph.namespace,
                lambda: graph.reset(0, TRAIN, loop.wait)[1].tick.stamp_ns,
                lambda bag: bag.wait_for(0, loop.wait, (interface.DECISION_TOPIC,)),
                topics=WITH_POLICY, cmd_vel_stamped=config.cmd_vel_stamped)
            observers.append(BagSceneWriter(recorder, config.sim_params))
        meta = {'set': eval_set.name, 'policy': eval_set.policy,
                'checkpoint': eval_set.checkpoint, 'realtime_rate': rate}
        results, latencies = [], ImageLatencies()
        checks: dict[str, int] = {}
        for seed in eval_set.seeds:
            with loop_graph.dead_named():
                result, trace, frames, latency = run_episode(graph, seed, eval_set.split, env,
                                                             loop, observers)
            results.append(result)
            latencies.sim += latency.sim
            latencies.wall += latency.wall
            latencies.inference += latency.inference
            latencies.skipped += latency.skipped
            for key, value in trace['checks'].items():
                checks[key] = checks.get(key, 0) + value
            write_episode(out, meta, result, trace, frames, recorder)
    finally:
        if recorder is not None:
            recorder.close()
        loop_graph.close()
    latency = {**latency_summary(latencies.sim, latencies.wall, loop.ctrl_dt,
                                 latencies.inference),
               'images_acted_on': len(latencies.sim), 'images_skipped': latencies.skipped}
    return set_entry(eval_set, results, realtime_rate=rate, decision_period_s=loop.period,
                     latency=latency, checks=checks)


def evaluate_closed_loop(run_dir: Path, seeds: dict[str, tuple[int, ...]],
                         rates: tuple[float, ...] = DEFAULT_RATES, out: Path | None = None,
                         record: bool = True, checkpoint: str = FINAL_MODEL,
                         live_port: int = 0) -> dict[str, Any]:
    """Evaluate the final model in lockstep and in real time at each rate on the same seeds.

    ``seeds`` maps a split ('train', 'heldout') to its seeds.  Writes ``results.json``,
    ``results.md``, ``episodes.csv``, traces and bags under ``out`` (default
    ``RUN/eval_closed_loop``).
    """
    config = run_config(run_dir)
    out = output_dir(out or run_dir / CLOSED_LOOP)
    if not (run_dir / checkpoint).is_file():
        raise EvaluationError(f'checkpoint {run_dir / checkpoint} not found; finish (or '
                              '--resume) the training run first')
    live = _live(live_port, config)
    entries: list[dict[str, Any]] = []
    closed_loop = {'rates': list(rates),
                   'ctrl_dt': SimConfig.from_params(config.sim_params).ctrl_dt}
    try:
        env = env_for_run(config, record)
        try:
            for split, split_seeds in seeds.items():
                name = f'dqn_{split}'
                entries.append(evaluate_set(env, run_dir, EvalSet(
                    name, SET_LABELS[name], 'dqn', checkpoint, split, split_seeds), out, record))
        finally:
            env.close()
        for rate in rates:
            for split, split_seeds in seeds.items():
                # the sets so far are written first: a failure or Ctrl-C later keeps them
                write_results(out, run_dir, config, entries, closed_loop=closed_loop)
                entries.append(evaluate_rate(run_dir, config, closed_loop_set(
                    rate, split, split_seeds, checkpoint), rate, out, record, live))
    finally:
        if live is not None:
            live.close()
    return write_results(out, run_dir, config, entries, closed_loop=closed_loop)


def _live(port: int, config: TrainConfig) -> Any:
    """Return the closed loop's live view (the policy's decisions too), or None when off."""
    if not port:
        return None
    from nav_gym.env.live_view import EnvLive
    from nav_sim.viz.topics import CLOSED_LOOP_TOPICS
    live = EnvLive(port, config.sim_params, topics=CLOSED_LOOP_TOPICS)
    print(f'live view: open {live.url} in Foxglove', flush=True)
    return live
