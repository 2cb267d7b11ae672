"""Evaluation of a tiny DQN through the real ROS graph.

The bag it records, its determinism, and the diagnosis of one of its failed episodes.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO, make_tiny_run
from nav_eval import seeds
from nav_eval.analysis.anatomy import goal_in_view
from nav_eval.errors import EvaluationError
from nav_eval.evaluation import runner
from nav_eval.evaluation.selection import load_episode
from nav_eval.evaluation.sets import DEFAULT_SETS, plan_sets, run_config
from nav_eval.reporting import run_report
from nav_eval.reporting.diagnosis_report import diagnose_run
from nav_gym.training.config import TrainConfig

SETS = ['random_train', 'dqn_heldout', 'early_train', 'explore_heldout']


@pytest.fixture(scope='module')
def run_dir(tmp_path_factory, spaces_only) -> Path:
    """Make a run directory with a tiny model (two checkpoints) and a 15-step episode limit.

    The model is the default learner's (Double DQN targets and every component the default
    turns on): evaluation, report and diagnosis run on its checkpoints.
    """
    return make_tiny_run(tmp_path_factory.mktemp('run'), spaces_only, max_episode_steps=15)


@pytest.fixture(scope='module')
def evaluated(run_dir) -> dict:
    sets = plan_sets(run_dir, SETS, (101, 102), (201, 202))
    return runner.evaluate(run_dir, sets, record=True)


def test_plan_uses_the_first_checkpoint_after_step_zero_as_early(run_dir):
    sets = plan_sets(run_dir, list(DEFAULT_SETS), seeds.WORKSHOP_TRAIN, seeds.WORKSHOP_HELDOUT)
    assert [s.name for s in sets] == list(DEFAULT_SETS)
    by_name = {s.name: s for s in sets}
    assert by_name['early_heldout'].checkpoint == 'checkpoints/dqn_32_steps.zip'
    assert by_name['dqn_train'].seeds == tuple(range(101, 111))
    assert by_name['dqn_heldout'].seeds == tuple(range(201, 211))
    assert by_name['dqn_heldout'].split == 'heldout'


def test_the_exploring_diagnosis_is_the_greedy_policy_plus_seeded_random_actions(run_dir):
    from nav_eval.evaluation.policies import DQNPolicy, ExploringDQNPolicy
    model = run_dir / 'final_model.zip'
    obs = np.random.default_rng(0).integers(0, 256, (3, 84, 84), dtype=np.uint8)
    never, always = ExploringDQNPolicy(model, 0.0), ExploringDQNPolicy(model, 1.0)
    greedy = DQNPolicy(model)
    never.begin_episode(201)
    greedy.begin_episode(201)  # the default learner's memory: the same history, step by step
    assert [never.act(obs) for _ in range(5)] == [greedy.act(obs) for _ in range(5)]

    def actions(seed: int) -> list[int]:
        always.begin_episode(seed)
        return [always.act(obs)[0] for _ in range(30)]
    assert actions(201) == actions(201) != actions(202)
    assert set(actions(201)) == {0, 1, 2}
    with pytest.raises(EvaluationError, match='epsilon'):
        ExploringDQNPolicy(model, 1.5)
    # a diagnosis on request, never part of the workshop's (deterministic) evaluation
    assert not [n for n in DEFAULT_SETS if n.startswith('explore')]
    [planned] = plan_sets(run_dir, ['explore_heldout'], (101,), (201,))
    assert (planned.policy, planned.checkpoint) == ('explore', 'final_model.zip')


def test_an_explore_set_acts_with_the_runs_own_epsilon_and_replays_exactly(run_dir, tmp_path):
    run = tmp_path / 'run'
    run.mkdir()
    (run / 'config.yaml').write_text(
        TrainConfig(max_episode_steps=15, exploration_final_eps=0.5).to_yaml())
    (run / 'final_model.zip').write_bytes((run_dir / 'final_model.zip').read_bytes())
    sets = plan_sets(run, ['explore_heldout'], (101,), (201, 202))
    [entry] = runner.evaluate(run, sets, record=False)['sets']
    assert entry['epsilon'] == 0.5
    trace = json.loads((run / 'eval' / 'traces' / 'explore_heldout' / 'seed_201.json')
                       .read_text())
    assert trace['epsilon'] == 0.5
    # half of the actions are drawn at random: some differ from the greedy choice
    assert any(s['action'] != int(np.argmax(s['q_values'])) for s in trace['steps'])
    # ... and the same seed draws them again (the diagnosis re-run relies on it)
    assert runner.rerun(run, trace) == [s['action'] for s in trace['steps']]
    assert run_report.checkpoint_name(entry) == 'final_model.zip, ε = 0.5'


def test_bad_requests_are_clear_errors(run_dir, tmp_path):
    with pytest.raises(EvaluationError, match='unknown evaluation set'):
        plan_sets(run_dir, ['dqn_validation'], (1,), (2,))
    with pytest.raises(EvaluationError, match='bad seed list'):
        seeds.parse_seeds('101-x')
    assert seeds.parse_seeds('101-103,110') == (101, 102, 103, 110)
    with pytest.raises(EvaluationError, match='not a training run'):
        run_config(tmp_path)
    with pytest.raises(EvaluationError, match='not found'):
        plan_sets(run_dir, ['dqn_train'], (1,), (2,), final='missing.zip')


def test_results_files_and_metrics(run_dir, evaluated):
    out = run_dir / 'eval'
    assert [s['name'] for s in evaluated['sets']] == SETS
    for entry in evaluated['sets']:
        assert entry['summary']['episodes'] == 2
        rates = [entry['summary'][k] for k in ('success_rate', 'collision_rate',
                                               'timeout_rate')]
        assert sum(rates) == pytest.approx(1.0)
        for episode in entry['episodes']:
            assert episode['length'] <= 15
            assert episode['outcome'] in ('success', 'collision', 'timeout')
            trace = json.loads((out / 'traces' / entry['name'] /
                                f"seed_{episode['seed']}.json").read_text())
            assert len(trace['steps']) == episode['length']
            assert sum(s['reward'] for s in trace['steps']) == pytest.approx(
                episode['return'], abs=1e-4)
            with np.load(out / 'traces' / entry['name'] /
                         f"seed_{episode['seed']}_frames.npz") as data:
                assert data['obs'].shape == (episode['length'] + 1, 3, 84, 84)
                # what each decision saw, for the failure anatomy without the frames
                assert [s['goal_in_view'] for s in trace['steps']] == [
                    goal_in_view(obs) for obs in data['obs'][:-1]]
            has_q = entry['policy'] in ('dqn', 'explore')
            assert all((s['q_values'] is not None) == has_q for s in trace['steps'])
            if entry['policy'] == 'dqn':  # deterministic predict = argmax of the logged Q-values
                assert all(s['action'] == int(np.argmax(s['q_values'])) for s in trace['steps'])
    assert (out / 'results.md').read_text().count('\n') == 2 + len(SETS)
    assert 'Random policy, training seeds (101–102)' in (out / 'results.md').read_text()
    assert (out / 'episodes.csv').read_text().count('\n') == 1 + 2 * len(SETS)
    assert evaluated['arena']['half_size'] == pytest.approx(1.0)


def test_every_set_is_recorded_as_an_mcap_bag(run_dir, evaluated):
    from nav_eval.recording.bags import episodes_in_bag, read_bag
    bag = run_dir / 'eval' / 'bags' / 'dqn_heldout'
    assert 'mcap' in (bag / 'metadata.yaml').read_text()
    annotations = episodes_in_bag(bag)
    entry = evaluated['sets'][1]
    assert [(a['seed'], a['outcome'], a['checkpoint']) for a in annotations] == [
        (e['seed'], e['outcome'], 'final_model.zip') for e in entry['episodes']]
    messages = read_bag(bag)
    images = next(v for k, v in messages.items() if k.endswith('camera/image_raw'))
    cmds = next(v for k, v in messages.items() if k.endswith('cmd_vel'))
    lengths = sum(e['length'] for e in entry['episodes'])
    assert len(images) == lengths + len(entry['episodes'])  # one per period + reset frames
    assert len(cmds) == lengths


def test_the_same_evaluation_twice_gives_identical_tables(run_dir, evaluated, tmp_path):
    sets = plan_sets(run_dir, SETS, (101, 102), (201, 202))
    again = runner.evaluate(run_dir, sets, out=tmp_path / 'again', record=False)
    assert again['sets'] == evaluated['sets']
    for name in ('results.md', 'episodes.csv'):
        assert (tmp_path / 'again' / name).read_text() == (run_dir / 'eval' / name).read_text()


def test_diagnosis_of_a_failed_episode(run_dir, evaluated):
    result = diagnose_run(run_dir)
    assert result['set'] == 'dqn_heldout' and result['outcome'] != 'success'
    status = {v['layer']: v['status'] for v in result['layers']}
    assert status['action timing'] == 'ok' and status['reward'] == 'ok'
    assert status['evaluation'] == 'ok'  # the re-run reproduced the actions
    assert any('reproduced all' in e for v in result['layers'] for e in v['evidence'])
    md = (run_dir / 'eval' / 'diagnosis.md').read_text()
    # the verdict names the first layer whose status is not ok, and the file says so
    flagged = [v for v in result['layers'] if v['status'] in ('broken', 'suspect')]
    assert flagged, 'an untrained tiny model fails for a reason the evidence shows'
    first = flagged[0]
    assert result['earliest_suspect_layer'] == first['layer']
    assert f"Earliest layer that looks {first['status']}: {first['layer']}" in md
    assert f"**Verdict:** {result['summary']}" in md
    for figure in result['figures']:
        assert (run_dir / figure).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def evaluate_command(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'nav_eval.evaluate', *args],
                          capture_output=True, text=True, timeout=120)


def one_line_error(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 1 and 'Traceback' not in result.stderr, result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith('nav-eval-evaluate: error: ')
    return line


def test_evaluate_command_reports_errors_without_traceback(tmp_path, run_dir):
    assert 'not a training run directory' in one_line_error(evaluate_command(str(tmp_path)))
    line = one_line_error(evaluate_command(str(run_dir), '--out', '/dev/null/x', '--sets',
                                           'random_train'))
    assert 'cannot create the output directory /dev/null/x (Not a directory)' in line
    line = one_line_error(evaluate_command(str(run_dir), '--heldout-seeds', '5-1,207'))
    assert "bad seed range '5-1'" in line
    line = one_line_error(evaluate_command(str(run_dir), '--sets', 'explore_heldout'))
    assert 'a diagnosis, not the evaluation' in line and '--out' in line
    binary = tmp_path / 'binary'
    binary.mkdir()
    (binary / 'config.yaml').write_bytes(bytes(range(256)) * 4)
    assert 'not a UTF-8 text file' in one_line_error(evaluate_command(str(binary)))


def test_seed_ranges_are_checked_before_they_are_built():
    start = time.perf_counter()
    with pytest.raises(EvaluationError, match=r'names 1000000000001 seeds, more than the '
                       r'100000 one list may name'):
        seeds.parse_seeds('0-1000000000000')
    assert time.perf_counter() - start < 1.0  # no list of a trillion seeds was built first
    with pytest.raises(EvaluationError, match='seeds are 0 to 2\\*\\*63 - 1'):
        seeds.parse_seeds(f'1,{2**63}')
    assert len(seeds.parse_seeds('0-99999')) == seeds.MAX_SEEDS


def test_a_large_evaluation_needs_the_flag_and_nothing_starts_without_it(tmp_path, run_dir):
    out = tmp_path / 'out'
    line = one_line_error(evaluate_command(str(run_dir), '--heldout-seeds', '1-100000',
                                           '--sets', 'dqn_heldout', '--out', str(out)))
    assert line == ('nav-eval-evaluate: error: 100000 episodes is more than 5000: add '
                    '--many-episodes to run them all')
    line = one_line_error(evaluate_command(str(run_dir), '--closed-loop', '--heldout-seeds',
                                           '1-2000', '--out', str(out)))
    assert '6000 episodes is more than 5000' in line  # lockstep + two rates
    assert not out.exists()


def test_a_reversed_seed_range_is_rejected():
    with pytest.raises(EvaluationError, match="bad seed range '5-1'"):
        seeds.parse_seeds('5-1,207')
    assert seeds.parse_seeds('5-5,207') == (5, 207)


def test_the_bags_replay_the_foxglove_layout(run_dir, evaluated):
    """Every topic of the shipped layout but the live-only ones is in the bag.

    The live-only ones are the training statistics and /diagnostics; the scene, robot and step
    topics follow the episodes, with the live view's types.
    """
    from nav_eval.recording.bags import read_bag
    from nav_sim.viz import topics as live_topics
    from nav_sim.viz.layout import LIVE_ONLY_TOPICS, referenced_topics
    layout = json.loads((REPO / 'config' / 'foxglove'
                         / 'visnav.json').read_text())
    # the policy node's tab comes from a closed-loop evaluation's bag (test_closed_loop)
    wanted = referenced_topics(layout) - set(LIVE_ONLY_TOPICS) - set(live_topics.POLICY_TOPICS)
    bag = run_dir / 'eval' / 'bags' / 'dqn_heldout'
    messages = read_bag(bag)
    assert wanted <= set(messages), f'missing in the bag: {sorted(wanted - set(messages))}'
    entry = evaluated['sets'][1]
    episodes, lengths = len(entry['episodes']), sum(e['length'] for e in entry['episodes'])
    scenes = messages[live_topics.SCENE_TOPIC]
    assert len(scenes) == episodes
    assert len(messages[live_topics.ROBOT_TOPIC]) == lengths + episodes
    assert len(messages[live_topics.OBSERVATION_TOPIC]) == lengths + episodes
    steps = [m for _, m in messages[live_topics.STEP_TOPIC]]
    assert len(steps) == lengths
    assert all(len(m.q_values) == 3 for m in steps)  # the DQN's Q-values
    assert all(m.action == int(np.argmax(m.q_values)) for m in steps)
    # each frame's scene topics share the camera image's stamp
    image_times = {t for t, _ in messages[live_topics.CAMERA_TOPIC]}
    assert {t for t, _ in messages[live_topics.ROBOT_TOPIC]} == image_times
    goals = [next(m for m in scene.markers if m.ns == 'goal') for _, scene in scenes]
    traces = [json.loads((run_dir / 'eval' / 'traces' / 'dqn_heldout' / f'seed_{e["seed"]}.json')
                         .read_text()) for e in entry['episodes']]
    assert [(g.pose.position.x, g.pose.position.y) for g in goals] == [
        pytest.approx(tuple(t['scenario']['goal']), abs=1e-3) for t in traces]


def test_a_recurrent_learner_is_evaluated_diagnosed_and_reported(tmp_path, spaces_only):
    """A checkpoint of the recurrent Q-network goes through evaluation, diagnosis and report.

    Through the ROS graph, the second episode's Q-values are the network's on windows built
    here by hand from its own frames (begun afresh: the first frame stands in before it, no
    previous action); its diagnosis re-runs it alone and reproduces every action; the report
    names the learner.
    """
    from nav_gym.training.learner import load_checkpoint
    run = tmp_path / 'recurrent'
    run.mkdir()
    make_tiny_run(run, spaces_only, steps=20, max_episode_steps=10, frame_stack=2,
                  recurrent=8)
    evaluated = runner.evaluate(run, plan_sets(run, ['dqn_heldout'], (101,), (201, 202)),
                                record=False)
    (entry,) = evaluated['sets']
    assert [e['seed'] for e in entry['episodes']] == [201, 202]
    trace, frames = load_episode(run / 'eval', 'dqn_heldout', 202)
    steps = trace['steps']
    model = load_checkpoint(run / 'final_model.zip', device='cpu')
    for t, step in enumerate(steps):
        planes = np.zeros((3, 84, 84), np.uint8)
        if t:
            planes[steps[t - 1]['action']] = 255
        window = np.concatenate([frames[max(t - 1, 0)], frames[t], planes])
        tensor, _ = model.policy.obs_to_tensor(window)
        q_values = model.q_net(tensor).detach().numpy()[0]
        assert np.allclose(step['q_values'], q_values, atol=1e-4), t
        assert step['action'] == int(np.argmax(step['q_values']))
    result = diagnose_run(run, 'dqn_heldout', 202)
    assert any('reproduced all' in e for v in result['layers'] for e in v['evidence'])
    text = run_report.write_report(run).read_text()
    assert 'an LSTM of 8 units' in text and '| recurrent | 8 |' in text
