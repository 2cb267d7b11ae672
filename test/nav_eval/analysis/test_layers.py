"""The failure-layer checks on constructed episodes, each with one deliberately broken layer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav_eval.analysis import failure_layers as layers
from nav_eval.analysis.diagnosis import diagnose
from nav_gym.env.config import EnvConfig
from nav_gym.policy import servo
from nav_sim.core.config import SimConfig

SIM, ENV = SimConfig(), EnvConfig()
FWD, TURN = ENV.forward_speed * SIM.ctrl_dt, ENV.turn_rate * SIM.ctrl_dt
GOAL = (1.0, 0.0)


def frame(pose, goal=GOAL, hfov=math.radians(SIM.camera_hfov_deg)):
    """Draw a grey observation with a green goal column where a camera at ``pose`` sees it."""
    rng = np.random.default_rng([int(abs(v) * 1e4) for v in pose])
    img = rng.integers(90, 140, size=(3, 84, 84)).astype(np.uint8)
    bearing = math.remainder(math.atan2(goal[1] - pose[1], goal[0] - pose[0]) - pose[2],
                             2 * math.pi)
    if abs(bearing) < hfov / 2:
        col = int(round((0.5 - bearing / hfov) * 83))
        img[:, 30:50, max(col - 2, 0):col + 3] = np.array([20, 220, 30], np.uint8)[:, None, None]
    return img


def episode(actions, mapping=(1, 0, -1), start=(0.0, 0.0, 0.4), goal=GOAL,
            final_event='none', q=None):
    """Simulate the kinematics; ``mapping`` is the yaw sign of (left, forward, right)."""
    pose, frames, steps = list(start), [frame(start, goal)], []
    previous = math.dist(start[:2], goal)
    for i, a in enumerate(actions):
        if a == 1:
            pose[0] += FWD * math.cos(pose[2])
            pose[1] += FWD * math.sin(pose[2])
        else:
            pose[2] += mapping[a] * TURN
        d = math.dist(pose[:2], goal)
        event = final_event if i == len(actions) - 1 else 'none'
        terms = {'progress': 2.0 * (previous - d), 'step': -0.01,
                 'goal': 5.0 if event == 'goal' else 0.0,
                 'collision': -1.0 if event == 'collision' else 0.0}
        steps.append({'step': i + 1, 'action': a, 'action_name': layers.ACTION_NAMES[a],
                      'reward': sum(terms.values()), 'reward_terms': terms, 'distance': d,
                      'pose': list(pose), 'event': event,
                      'q_values': None if q is None else q[i]})
        previous = d
        frames.append(frame(pose, goal))
    trace = {'set': 'dqn_heldout', 'seed': 201, 'split': 'heldout', 'policy': 'dqn',
             'checkpoint': 'final_model.zip', 'outcome': 'timeout',
             'scenario': {'start': list(start), 'goal': list(goal),
                          'initial_distance': math.dist(start[:2], goal)},
             'steps': steps}
    return trace, np.stack(frames)


def servo_actions(start=(0.0, 0.0, 0.4), n=30):
    """Return a visual servo's actions from the constructed frames (a policy that works)."""
    trace, frames = episode([], start=start)
    actions, pose = [], list(start)
    for _ in range(n):
        band = servo.centre_band(TURN, math.radians(SIM.camera_hfov_deg))
        want = servo.servo_action(servo.goal_bearing(frame(pose)), band)
        a = 0 if want is None else want
        actions.append(a)
        trace, frames = episode(actions, start=start)
        pose = trace['steps'][-1]['pose']
    return actions


def test_goal_bearing_and_servo():
    assert servo.goal_bearing(frame((0, 0, 0))) == pytest.approx(0.0, abs=0.05)
    assert servo.goal_bearing(frame((0, 0, 0.3))) > 0.2      # goal to the right in the image
    assert servo.goal_bearing(frame((0, 0, math.pi))) is None  # behind the robot
    assert servo.servo_action(-0.5) == 0 and servo.servo_action(0.0) == 1


def test_a_healthy_episode_has_no_broken_layer():
    trace, frames = episode(servo_actions())
    result = diagnose(trace, frames, SIM, ENV, rerun_actions=[s['action'] for s in
                                                                trace['steps']])
    status = {v['layer']: v['status'] for v in result['layers']}
    assert status == {layer: 'ok' for layer in layers.LAYERS}, result['layers']
    assert result['earliest_suspect_layer'] is None


def test_swapped_action_mapping_is_found_as_the_earliest_broken_layer():
    actions = servo_actions()
    trace, frames = episode(actions, mapping=(-1, 0, 1))  # left turns clockwise
    result = diagnose(trace, frames, SIM, ENV)
    assert result['earliest_suspect_layer'] == 'action timing'
    assert 'did not move the robot as named' in result['summary']
    verdict = result['layers'][1]
    assert verdict['status'] == 'broken' and 'did not move the robot as named' in \
        verdict['evidence'][0]


def test_wrong_action_duration_is_flagged():
    trace, frames = episode(servo_actions())
    sim = SimConfig(action_repeat=3)  # the env believes periods are half as long
    result = diagnose(trace, frames, sim, ENV)
    assert result['layers'][1]['status'] == 'broken'
    assert 'off the configured' in ' '.join(result['layers'][1]['evidence'])


def test_blank_and_stale_frames_break_the_observation_layer():
    trace, frames = episode(servo_actions())
    frames[5] = 0
    frames[9] = frames[8]
    v = layers.check_observations(frames, trace['steps'])
    assert v.status == 'broken'
    assert any('blank' in e for e in v.evidence) and any('stale' in e for e in v.evidence)
    assert diagnose(trace, frames, SIM, ENV)['earliest_suspect_layer'] == 'visual observation'


def test_a_goal_never_in_view_is_suspect():
    trace, frames = episode([0] * 5, start=(0.0, 0.0, math.pi))
    assert layers.check_observations(frames, trace['steps']).status == 'suspect'


def test_tampered_reward_is_broken():
    trace, frames = episode(servo_actions())
    k = next(i for i, s in enumerate(trace['steps']) if s['action'] == 1 and i > 2)
    trace['steps'][k]['reward_terms']['progress'] *= 10
    trace['steps'][k]['reward'] = sum(trace['steps'][k]['reward_terms'].values())
    v = layers.check_reward(trace['steps'], trace['scenario']['initial_distance'],
                            {'progress_weight': 2.0, 'step_penalty': -0.01, 'goal_reward': 5.0,
                             'collision_penalty': -1.0})
    assert v.status == 'broken' and f'steps [{k + 1}]' in v.evidence[0]


def test_policy_turning_away_from_a_visible_goal_is_suspect():
    # the goal is in view, left of centre, and the policy keeps turning away from it
    trace, frames = episode([0] * 3 + [2, 0] * 6, start=(0.0, 0.0, -0.2))
    v = layers.check_policy(trace['steps'], frames, 'timeout', None)
    assert v.status == 'suspect' and 'not learned to approach' in ' '.join(v.evidence)


def test_spinning_and_dithering_are_described():
    notes = layers.behaviour_notes([{'action': 0}] * 30 + [{'action': 0}, {'action': 2}] * 3,
                                   TURN)
    assert any('spins in place' in n for n in notes)
    assert any('dithers' in n for n in notes)


def test_nondeterministic_evaluation_and_settings_mismatch_are_broken():
    trace, _ = episode(servo_actions())
    logged = [s['action'] for s in trace['steps']]
    v = layers.check_evaluation(trace, {'forward_speed': 0.12}, {'forward_speed': 0.2},
                                logged[:-1] + [(logged[-1] + 1) % 3])
    assert v.status == 'broken'
    text = ' '.join(v.evidence)
    assert 'not deterministic' in text and 'differ from training' in text


def test_the_diagnosed_failure_is_the_final_models_first_then_the_early_checkpoints(tmp_path):
    import json

    from nav_eval.errors import DiagnosisError
    from nav_eval.evaluation.selection import pick_episode

    def write(outcomes: dict) -> None:
        sets = [{'name': name, 'episodes': [{'seed': 201 + i, 'outcome': o}
                                            for i, o in enumerate(found)]}
                for name, found in outcomes.items()]
        (tmp_path / 'results.json').write_text(json.dumps({'sets': sets}))

    ok = ['success'] * 3
    write({'dqn_heldout': ok, 'dqn_train': ['success', 'success', 'timeout'],
           'early_heldout': ['collision'] * 3})
    assert pick_episode(tmp_path, None, None) == ('dqn_train', 203)
    write({'dqn_heldout': ok, 'dqn_train': ok,
           'early_heldout': ['success', 'collision', 'timeout']})
    assert pick_episode(tmp_path, None, None) == ('early_heldout', 202)
    write({'dqn_heldout': ok, 'dqn_train': ok, 'early_heldout': ok, 'early_train': ok})
    with pytest.raises(DiagnosisError, match='nothing to diagnose'):
        pick_episode(tmp_path, None, None)


def test_diagnosis_checks_a_run_against_its_own_reward_weights(tmp_path):
    """A run trained with other reward weights: its rewards are right by its own config."""
    import json

    from nav_eval.reporting.diagnosis_report import diagnose_run
    from nav_gym.training.config import TrainConfig
    from nav_gym.training.run_dir import frames_path, trace_path

    weights = {'progress_weight': 3.0, 'step_penalty': -0.05, 'goal_reward': 10.0,
               'collision_penalty': -2.0}
    trace, frames = episode(servo_actions(n=6), final_event='collision')
    for s in trace['steps']:
        progress = s['reward_terms']['progress'] / 2.0
        s['reward_terms'] = {'progress': 3.0 * progress, 'step': -0.05, 'goal': 0.0,
                             'collision': -2.0 if s['event'] == 'collision' else 0.0}
        s['reward'] = sum(s['reward_terms'].values())
    trace['outcome'] = 'collision'
    (tmp_path / 'config.yaml').write_text(TrainConfig(**weights).to_yaml())
    path = trace_path(tmp_path / 'eval', 'dqn_heldout', 201)
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(trace))
    np.savez_compressed(frames_path(path), obs=frames)
    (tmp_path / 'eval' / 'results.json').write_text(json.dumps({'sets': [
        {'name': 'dqn_heldout', 'episodes': [{'seed': 201, 'outcome': 'collision'}]}]}))
    status = {v['layer']: v['status'] for v in diagnose_run(tmp_path, replay=False)['layers']}
    assert status['reward'] == 'ok'
    # the same episode judged by the default weights would not follow the formula
    assert layers.check_reward(trace['steps'], trace['scenario']['initial_distance'], {
        k: getattr(ENV, k) for k in weights}).status == 'broken'
