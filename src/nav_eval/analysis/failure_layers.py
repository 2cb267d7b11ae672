"""Failure-layer checks of one evaluation episode (pure: numpy only, no ROS, no torch).

The workshop's failure-layer model, in order: visual observation -> action selection/timing ->
reward -> exploration/training -> evaluation.  Each check looks at the evidence of one layer and
returns a :class:`LayerVerdict`: ``broken`` (the layer violates its contract), ``suspect`` (it
works as specified but the evidence points at it) or ``ok``.  The earliest layer that is not
``ok`` is where to look first.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nav_gym.env.actions import ACTION_NAMES
from nav_gym.policy.servo import goal_bearing, servo_action
from nav_gym.training.run_dir import EVAL_SETTINGS
from nav_sim.core.events import EVENT_COLLISION, EVENT_GOAL, EVENT_NONE, OUTCOME_COLLISION

LAYERS = ('visual observation', 'action timing', 'reward', 'training / exploration',
          'evaluation')


@dataclass
class LayerVerdict:
    """What one layer's evidence says."""

    layer: str
    status: str = 'ok'  # ok | suspect | broken | n/a
    evidence: list[str] = field(default_factory=list)
    reason: str = ''  # the first finding at the verdict's (most severe) status

    def flag(self, status: str, text: str) -> None:
        """Add a finding; the verdict becomes ``status`` if that is more severe."""
        order = ('n/a', 'ok', 'suspect', 'broken')
        if order.index(status) > order.index(self.status):
            self.status, self.reason = status, text
        self.evidence.append(text)

    def note(self, text: str) -> None:
        """Add evidence that changes no verdict."""
        self.evidence.append(text)


def check_observations(frames: np.ndarray, steps: Sequence[dict]) -> LayerVerdict:
    """Check shape and dtype, blank and stale frames, and whether the goal is ever in view."""
    v = LayerVerdict(LAYERS[0])
    if frames.ndim != 4 or frames.shape[1:] != (3, 84, 84) or frames.dtype != np.uint8:
        v.flag('broken', f'observations are {frames.shape} {frames.dtype}, the contract is '
                         '(3, 84, 84) uint8')
        return v
    v.note(f'{len(frames)} observations, (3, 84, 84) uint8, values {int(frames.min())}-'
           f'{int(frames.max())}')
    flat = [i for i, f in enumerate(frames) if int(f.max()) - int(f.min()) < 10]
    if flat:
        v.flag('broken', f'{len(flat)} blank/constant frames (first at step {flat[0]})')
    poses = [None] + [s['pose'] for s in steps]
    stale = [i for i in range(2, len(frames)) if np.array_equal(frames[i], frames[i - 1])
             and _moved(poses[i - 1], poses[i])]
    if stale:
        v.flag('broken', f'{len(stale)} frames identical to the previous one although the '
                         f'robot moved (stale images; first at step {stale[0]})')
    visible = [i for i, f in enumerate(frames) if goal_bearing(f) is not None]
    share = len(visible) / len(frames)
    if not visible:
        v.flag('suspect', 'the goal is never visible in the episode: the policy had no visual '
                          'cue (occluded or outside the field of view throughout)')
    else:
        v.note(f'goal visible in {len(visible)}/{len(frames)} frames ({share:.0%}), first at '
               f'step {visible[0]}')
    return v


def _moved(a: Sequence[float] | None, b: Sequence[float]) -> bool:
    if a is None:
        return False
    return math.hypot(b[0] - a[0], b[1] - a[1]) > 1e-4 or abs(_wrap(b[2] - a[2])) > 1e-3


def _wrap(angle: float) -> float:
    return math.remainder(angle, 2 * math.pi)


def arc_chord(speed: float, rate: float, duration: float) -> float:
    """Straight-line displacement of one period of an arc (0 for a turn in place)."""
    if rate == 0:
        return speed * duration
    return abs(2.0 * speed / rate * math.sin(rate * duration / 2.0))


def check_actions(steps: Sequence[dict], start_pose: Sequence[float], forward_step: float,
                  turn_step: float, turn_advance: float = 0.0) -> LayerVerdict:
    """Each action moved the robot as named, by the configured amount per control period.

    ``forward_step`` (m), ``turn_step`` (rad) and ``turn_advance`` (m, the chord of an arc turn;
    0 for turns in place) are what one full period of the actions should do.
    """
    v = LayerVerdict(LAYERS[1])
    wrong, short = [], []
    previous = list(start_pose)
    for s in steps:
        x, y, yaw = s['pose']
        moved = math.hypot(x - previous[0], y - previous[1])
        turned = _wrap(yaw - previous[2])
        full = s['event'] == EVENT_NONE  # a goal/collision stops the period early
        name = ACTION_NAMES[s['action']]
        if name == 'forward':
            heading = math.atan2(y - previous[1], x - previous[0])
            ok = abs(turned) < 1e-3 and (moved < 1e-6 or abs(_wrap(heading - previous[2]))
                                         < 0.05)
            ok = ok and (moved > 0 or not full)
            amount, expected = moved, forward_step
        else:
            sign = 1.0 if name == 'left' else -1.0
            ok = sign * turned > 0 or (not full and turned == 0)
            ok = ok and moved <= 1.1 * turn_advance + 1e-4
            if moved > 1e-4:  # an arc advances along the mean heading of the period
                heading = math.atan2(y - previous[1], x - previous[0])
                ok = ok and abs(_wrap(heading - previous[2] - turned / 2)) < 0.1
            amount, expected = abs(turned), turn_step
        if not ok:
            wrong.append(s['step'])
        elif full and abs(amount - expected) > 0.1 * expected:
            short.append(s['step'])
        previous = [x, y, yaw]
    if wrong:
        v.flag('broken', f'{len(wrong)} of {len(steps)} actions did not move the robot as '
                         f'named (steps {wrong[:8]}): check the action -> cmd_vel mapping')
    if short:
        v.flag('broken', f'{len(short)} actions moved by more than 10% off the configured '
                         f'{forward_step * 100:.1f} cm / {math.degrees(turn_step):.1f}° per '
                         f'period (steps {short[:8]}): check action timing')
    if not wrong and not short:
        v.note(f'all {len(steps)} actions moved as named: forward {forward_step * 100:.1f} cm, '
               f'turns {math.degrees(turn_step):.1f}° per period')
    v.evidence.extend(behaviour_notes(steps, turn_step))
    return v


def behaviour_notes(steps: Sequence[dict], turn_step: float) -> list[str]:
    """Describe the action histogram, longest same-direction spin and left/right dithering."""
    actions = [s['action'] for s in steps]
    counts = Counter(ACTION_NAMES[a] for a in actions)
    notes = ['actions: ' + ', '.join(f'{n} {counts[n]}' for n in ACTION_NAMES)]
    longest, run = 0, 0
    for i, a in enumerate(actions):
        run = run + 1 if a != 1 and i and a == actions[i - 1] else (1 if a != 1 else 0)
        longest = max(longest, run)
    if longest * turn_step >= 2 * math.pi:
        notes.append(f'spins in place: {longest} consecutive turns in one direction '
                     f'({math.degrees(longest * turn_step):.0f}°)')
    dither = sum(1 for a, b in zip(actions, actions[1:], strict=False) if {a, b} == {0, 2})
    if dither >= 4:
        notes.append(f'dithers: {dither} left<->right reversals')
    return notes


def check_reward(steps: Sequence[dict], initial_distance: float,
                 weights: dict[str, float]) -> LayerVerdict:
    """Recompute every reward term from the distances and events; compare with the log."""
    v = LayerVerdict(LAYERS[2])
    previous, bad, sums = initial_distance, [], Counter()
    for s in steps:
        # written out again on purpose, not nav_gym.env.reward.reward_terms: a check that
        # called the env's own formula would agree with it when the formula is wrong
        expected = {'progress': weights['progress_weight'] * (previous - s['distance']),
                    'step': weights['step_penalty'],
                    'goal': weights['goal_reward'] if s['event'] == EVENT_GOAL else 0.0,
                    'collision': weights['collision_penalty'] if s['event'] == EVENT_COLLISION
                    else 0.0}
        logged = s['reward_terms']
        if any(abs(expected[k] - logged.get(k, math.nan)) > 1e-4 for k in expected) or \
                abs(sum(logged.values()) - s['reward']) > 1e-4:
            bad.append(s['step'])
        for k, value in logged.items():
            sums[k] += value
        previous = s['distance']
    if bad:
        v.flag('broken', f'{len(bad)} steps whose reward does not follow the formula '
                         f'(steps {bad[:8]})')
    total = sum(sums.values())
    net = initial_distance - (steps[-1]['distance'] if steps else initial_distance)
    v.note(f'return {total:+.3f} = progress {sums["progress"]:+.3f} + step {sums["step"]:+.3f} '
           f'+ goal {sums["goal"]:+.3f} + collision {sums["collision"]:+.3f}; distance '
           f'{initial_distance:.3f} -> {initial_distance - net:.3f} m')
    if sums['progress'] > 0 and net <= 0:
        v.flag('broken', 'progress reward is positive while the distance did not fall')
    return v


def check_policy(steps: Sequence[dict], frames: np.ndarray, outcome: str,
                 training: dict[str, Any] | None, band: float = 0.3) -> LayerVerdict:
    """Did the policy act sensibly on what it saw?  Plus the training curve's evidence."""
    v = LayerVerdict(LAYERS[3])
    pairs = [(servo_action(goal_bearing(frames[i]), band), s['action'])
             for i, s in enumerate(steps)]
    seen = [(want, got) for want, got in pairs if want is not None]
    if seen:
        agree = sum(w == g for w, g in seen) / len(seen)
        text = (f'with the goal in view ({len(seen)} steps) the policy chose the action that '
                f'points at it {agree:.0%} of the time')
        (v.flag('suspect', text + ': it has not learned to approach a visible goal')
         if agree < 0.6 else v.note(text))
    q = [s['q_values'] for s in steps if s.get('q_values')]
    if q:
        arr = np.array(q)
        spread = float(np.mean(arr.max(1) - arr.min(1)))
        v.note(f'mean Q {arr.mean():+.3f}, mean spread between best and worst action '
               f'{spread:.3f}')
    if outcome == OUTCOME_COLLISION:
        v.flag('suspect', 'the frozen policy drove into an obstacle or wall')
    if training:
        v.note(f"training: {training['episodes']} episodes, success rate over the last "
               f"{training['tail']} {training['tail_success']:.0%}, final epsilon "
               f"{training['final_eps']}")
        if training['tail_success'] < 0.5:
            v.flag('suspect', 'training never reached a reliable success rate')
    return v


def check_evaluation(trace: dict, eval_config: dict | None, run_config: dict | None,
                     rerun_actions: list[int] | None) -> LayerVerdict:
    """Compare evaluation settings with the run's and the episode with its re-run.

    Settings compared are those both sides record (an older evaluation has fewer).
    """
    v = LayerVerdict(LAYERS[4])
    if eval_config and run_config:
        keys = [k for k in EVAL_SETTINGS if k in eval_config and k in run_config]
        diff = [k for k in keys if eval_config.get(k) != run_config.get(k)]
        if diff:
            v.flag('broken', f'evaluation settings differ from training: {diff}')
        else:
            v.note('evaluation used the training settings (sim, action speeds, time limit, '
                   'reward weights)')
    if rerun_actions is not None:
        logged = [s['action'] for s in trace['steps']]
        if rerun_actions != logged:
            first = next((i for i, (a, b) in enumerate(zip(rerun_actions, logged,
                                                           strict=False)) if a != b),
                         min(len(rerun_actions), len(logged)))
            v.flag('broken', f're-running seed {trace["seed"]} gave different actions '
                             f'(first at step {first + 1}): evaluation is not deterministic')
        else:
            v.note(f're-running seed {trace["seed"]} reproduced all {len(logged)} actions')
    return v
