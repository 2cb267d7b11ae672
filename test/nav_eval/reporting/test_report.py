"""The result report and its figures, on small run directories built in tmp_path."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pytest

from helpers import REPO
from nav_eval import report
from nav_eval.reporting import plots, run_report

ARENA = {'half_size': 1.0, 'robot_radius': 0.037, 'goal_radius': 0.1, 'goal_marker_radius': 0.05,
         'shapes': [{'name': 'obstacle_0', 'kind': 'box', 'half_x': 0.2, 'half_y': 0.05},
                    {'name': 'obstacle_1', 'kind': 'box', 'half_x': 0.1, 'half_y': 0.1},
                    {'name': 'obstacle_2', 'kind': 'cylinder', 'half_x': 0.08, 'half_y': 0.08}]}
OBSTACLES = [{'slot': 0, 'x': 0.3, 'y': -0.2, 'yaw': math.pi / 6},
             {'slot': 2, 'x': -0.5, 'y': 0.5, 'yaw': 0.0}]
OUTCOMES = {201: 'success', 202: 'collision', 203: 'timeout',
            101: 'success', 102: 'success', 103: 'collision'}
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
EXPERIMENTS = ('# Experiments\n\n- Attempt 1: lowered the learning rate to 5e-5; held-out '
               'success 40%.\n')


def write_json(path: Path, data: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))


def write_png(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1], [1, 0])
    fig.savefig(path)
    plt.close(fig)


def make_training(run: Path, episodes: int = 30) -> None:
    """summary.json, config.yaml, monitor.csv and empty checkpoint files."""
    config = {'learning_rate': 0.0001, 'buffer_size': 50000, 'learning_starts': 2000,
              'batch_size': 32, 'gamma': 0.99, 'target_update_interval': 1000,
              'exploration_fraction': 0.25, 'exploration_final_eps': 0.05, 'seed': 9,
              'max_episode_steps': 250, 'sim_params': {'sim_dt': 0.032}, 'forward_speed': 0.1,
              'turn_rate': 1.5}
    write_json(run / 'summary.json', {
        'wall_clock_s': 3725.0, 'steps_per_s': 13.42, 'env_share': 0.712, 'env_time_s': 2652.2,
        'num_timesteps': 5000, 'total_timesteps': 5000, 'episodes': episodes,
        'interrupted': False, 'config': config, 'sessions': [{'wall_clock_s': 3725.0}],
        'wall_clock_total_s': 3725.0})
    (run / 'config.yaml').write_text('learning_rate: 0.0001\nseed: 9\n')
    rng = np.random.default_rng(0)
    lines = ['#{"t_start": 1700000000.0, "env_id": "visnav/Navigation-v0"}',
             'r,l,t,is_success,event']
    for i in range(episodes):
        success = bool(i > 15 and rng.random() < 0.7)
        event = 'goal' if success else rng.choice(['collision', 'none'])
        lines.append(f'{rng.normal(2 if success else -1):.3f},{rng.integers(20, 250)},'
                     f'{10.0 * i:.1f},{success},{event}')
    (run / 'monitor.csv').write_text('\n'.join(lines) + '\n')
    for steps in (0, 2000, 4000):
        (run / 'checkpoints').mkdir(exist_ok=True)
        (run / 'checkpoints' / f'dqn_{steps}_steps.zip').write_bytes(b'')


def make_trace(set_name: str, seed: int, outcome: str, length: int) -> dict[str, Any]:
    split = 'heldout' if seed > 200 else 'train'
    start, goal = (-0.6, -0.6, 0.3), (0.5, 0.4)
    steps = []
    for i in range(1, length + 1):
        f = i / length * (1.0 if outcome == 'success' else 0.6)
        pose = [start[0] + f * (goal[0] - start[0]), start[1] + f * (goal[1] - start[1]), 0.7]
        event = {'success': 'goal', 'collision': 'collision'}.get(outcome, 'none')
        steps.append({'step': i, 'action': 1, 'action_name': 'forward', 'reward': 0.01,
                      'reward_terms': {'progress': 0.02, 'step': -0.01, 'goal': 0.0,
                                       'collision': 0.0},
                      'distance': 1.0 - f, 'pose': pose,
                      'event': event if i == length else 'none', 'q_values': [0.1, 0.3, 0.2]})
    return {'set': set_name, 'policy': 'dqn', 'checkpoint': 'final_model.zip', 'seed': seed,
            'split': split, 'outcome': outcome,
            'scenario': {'seed': seed, 'split': split, 'layout': 3, 'start': list(start),
                         'goal': list(goal), 'initial_distance': 1.49, 'obstacles': OBSTACLES},
            'steps': steps}


def eval_set(name: str, label: str, policy: str, checkpoint: str | None, split: str,
             summary: dict[str, float]) -> dict[str, Any]:
    seeds = [201, 202, 203] if split == 'heldout' else [101, 102, 103]
    episodes = [{'seed': s, 'split': split, 'outcome': OUTCOMES[s], 'length': 40 + s % 10,
                 'return': 1.5, 'initial_distance': 1.49, 'final_distance': 0.08,
                 'path_length': 1.6, 'spl': 0.9} for s in seeds]
    return {'name': name, 'label': label, 'policy': policy, 'checkpoint': checkpoint,
            'split': split, 'seeds': seeds, 'summary': {'episodes': 3, **summary},
            'episodes': episodes}


def make_evaluation(run: Path) -> None:
    """validation.json, eval/results.json, traces + frames, diagnosis.{json,md}."""
    write_json(run / 'validation.json', [
        {'name': 'Observation shape', 'expected': '(3, 84, 84)', 'measured': '(3, 84, 84)',
         'passed': True},
        {'name': 'Observation dtype', 'expected': 'uint8', 'measured': 'uint8', 'passed': True},
        {'name': 'Observation range', 'expected': '0-255, not constant',
         'measured': 'min 3, max 251', 'passed': True},
        {'name': 'Action space', 'expected': 'Discrete(3)', 'measured': 'Discrete(3)',
         'passed': True},
        {'name': 'check_env() (SB3)', 'expected': 'no errors, no warnings',
         'measured': "1 warnings: ['a | b']", 'passed': False}])
    rates = lambda s, c, t, length, spl, ret: {  # noqa: E731
        'success_rate': s, 'collision_rate': c, 'timeout_rate': t, 'mean_length': length,
        'mean_spl': spl, 'mean_return': ret}
    sets = [eval_set('random_train', 'Random policy (training seeds)', 'random', None, 'train',
                     rates(0.0, 0.6667, 0.3333, 88.0, 0.0, -1.234)),
            eval_set('dqn_train', 'DQN final (training seeds)', 'dqn', 'final_model.zip',
                     'train', rates(0.6667, 0.3333, 0.0, 45.3333, 0.6012, 3.1)),
            eval_set('dqn_heldout', 'DQN final (held-out seeds)', 'dqn', 'final_model.zip',
                     'heldout', rates(0.3333, 0.3333, 0.3333, 63.2, 0.55, 2.5)),
            eval_set('early_train', 'DQN early (training seeds)', 'dqn',
                     'checkpoints/dqn_2000_steps.zip', 'train',
                     rates(0.1, 0.5, 0.4, 120.5, 0.05, -0.5))]
    write_json(run / 'eval' / 'results.json', {'arena': ARENA, 'config': {}, 'sets': sets})
    rng = np.random.default_rng(1)
    for set_name, seed in (('dqn_heldout', 201), ('dqn_heldout', 202), ('dqn_heldout', 203),
                           ('dqn_train', 101)):
        trace = make_trace(set_name, seed, OUTCOMES[seed], 12)
        folder = run / 'eval' / 'traces' / set_name
        write_json(folder / f'seed_{seed}.json', trace)
        frames = rng.integers(0, 256, size=(13, 3, 84, 84), dtype=np.uint8)
        np.savez_compressed(folder / f'seed_{seed}_frames.npz', obs=frames)
    stem = 'diagnosis_dqn_heldout_seed_202'  # as nav-eval-diagnose names them
    write_png(run / 'eval' / 'figures' / f'{stem}_trace.png')
    write_png(run / 'eval' / 'figures' / f'{stem}_frames.png')
    write_json(run / 'eval' / 'diagnosis.json', {
        'set': 'dqn_heldout', 'seed': 202, 'outcome': 'collision',
        'earliest_suspect_layer': 'exploration / training', 'summary': 'policy drives into box',
        'layers': [{'layer': 'visual observation', 'status': 'ok', 'evidence': ['fine']}],
        'figures': [f'eval/figures/{stem}_trace.png', f'eval/figures/{stem}_frames.png']})
    (run / 'eval' / 'diagnosis.md').write_text(
        '**Verdict:** the policy drives into the box (seed 202).\n\n'
        f'![trace](figures/{stem}_trace.png)\n\n<details><summary>Every step</summary>\n\n'
        '| step | action |\n|---|---|\n| 1 | fwd<br>q 0.3 |\n\n</details>\n')


@pytest.fixture(scope='module')
def full_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    run = tmp_path_factory.mktemp('runs') / 'dqn_test'
    run.mkdir()
    make_training(run)
    make_evaluation(run)
    experiments = run.parent / 'experiments.md'
    experiments.write_text(EXPERIMENTS)
    path = run_report.write_report(run, experiments)
    return path, path.read_text()


def test_report_has_every_section_in_order(full_report: tuple[Path, str]) -> None:
    path, text = full_report
    assert path.name == 'Result.md'
    positions = [text.index(f'## {title}\n') for title in run_report.SECTIONS]
    assert positions == sorted(positions)
    assert 'Missing' not in text


def test_evaluation_table_has_the_results(full_report: tuple[Path, str]) -> None:
    text = full_report[1]
    section = text.split('## 4. Evaluation')[1].split('## 5.')[0]
    assert ('| Random policy (training seeds) | random policy | train | 3 | 0% | 67% | 33% | '
            '88.0 | 0.000 | -1.234 |') in section
    assert ('| DQN final (held-out seeds) | final_model.zip | heldout | 3 | 33% | 33% | 33% | '
            '63.2 | 0.550 | 2.500 |') in section
    assert '| 202 | collision | 42 | 1.50 | 1.49 | 0.08 | 1.60 | 0.90 |' in section


def test_early_vs_final_compares_the_same_seeds(full_report: tuple[Path, str]) -> None:
    section = full_report[1].split('## 3.')[1].split('## 4.')[0]
    assert '| DQN early (training seeds) | dqn_2000_steps.zip (2,000 steps) | train | 3 | 10% |' \
        in section
    assert '| DQN final (training seeds) | final_model.zip | train | 3 | 67% |' in section
    assert 'success rate 10% with dqn_2000_steps.zip (2,000 steps) vs 67% with ' \
        'final_model.zip on the same seeds' in section


def test_checks_training_and_verbatim_sections(full_report: tuple[Path, str]) -> None:
    text = full_report[1]
    assert ("| check_env() (SB3) | no errors, no warnings | 1 warnings: ['a \\| b'] | **FAIL** |"
            in text)
    assert '4 of 5 checks passed' in text
    assert '| Wall-clock time | 1 h 02 min (3,725 s) |' in text
    assert '| Environment share of the time | 71.2% (2652 s in the environment) |' in text
    assert '| learning_rate | 0.0001 |' in text
    assert 'checkpoints at steps: 0, 2,000, 4,000' in text
    assert '**Verdict:** the policy drives into the box (seed 202).' in text
    assert EXPERIMENTS.strip() in text
    reproduce = text.split('## 8. Reproduce')[1]
    assert 'nav-eval-evaluate runs/dqn_test\n' in reproduce  # no machine-specific path
    # its config predates the learner's settings: they are given their values of that time,
    # not today's defaults (a 4-frame stack...)
    assert ('nav-gym-train --config runs/dqn_test/config.yaml --double-q false --n-steps 1 '
            '--frame-stack 1 --previous-action false --reset-interval 0 --gradient-steps 1 '
            '--run-name dqn_test_again') in reproduce


def test_every_referenced_image_is_a_png(full_report: tuple[Path, str]) -> None:
    path, text = full_report
    images = re.findall(r'!\[[^\]]*\]\(([^)]+)\)', text)
    names = {Path(i).name for i in images}
    assert {'training_curves.png', 'trajectory_grid.png', 'trajectory_success.png',
            'trajectory_failure.png', 'contact_sheet.png',
            'diagnosis_dqn_heldout_seed_202_trace.png',
            'diagnosis_dqn_heldout_seed_202_frames.png'} <= names
    assert len(images) == len(names)  # the diagnosis figure named twice is shown once
    for image in images:
        data = (path.parent / image).read_bytes()
        assert data.startswith(PNG_MAGIC), image
        assert len(data) > 5000, image


def test_failure_shown_is_the_diagnosed_episode(full_report: tuple[Path, str]) -> None:
    text = full_report[1]
    assert 'Failure: dqn_heldout seed 202 (collision, 12 steps)' in text
    assert 'Success: dqn_heldout seed 201 (success, 12 steps)' in text
    # the diagnosis shows the failure's frames, so the contact sheet shows the success's
    assert 'Policy observations (3x84x84) of dqn_heldout seed 201 (success)' in text


def test_html_is_self_contained(full_report: tuple[Path, str]) -> None:
    page = full_report[0].with_suffix('.html').read_text()
    assert '<table>' in page and '<h2' in page
    assert page.count('data:image/png;base64,') >= 7
    assert 'src="figures/' not in page
    assert '<td>202</td>' in page  # a table inside a collapsed <details> block is rendered
    assert '<td>fwd<br>q 0.3</td>' in page  # so is the one of the verbatim diagnosis


def test_missing_inputs_are_named_not_fatal(tmp_path: Path) -> None:
    run = tmp_path / 'dqn_bare'
    run.mkdir()
    make_training(run)
    (run / 'config.yaml').unlink()
    text = run_report.write_report(run).read_text()
    for title in run_report.SECTIONS:
        assert f'## {title}\n' in text
    assert 'nav-gym-validate --json' in text
    assert text.count('**Missing:**') >= 6
    assert 'Produce it with `nav-eval-evaluate ' in text
    assert 'Produce it with `nav-eval-diagnose ' in text
    assert '**MISSING**' in text
    assert (run / 'report' / 'figures' / 'training_curves.png').is_file()
    assert (run / 'report' / 'Result.html').is_file()


def test_command_errors_readably_on_a_non_run_dir(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        report.main([str(tmp_path), '--ros-args', '-r', '__node:=report'])
    assert exit_info.value.code == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith('nav-eval-report: error:') and 'not a run directory' in err
    assert len(err.splitlines()) == 1


def test_command_prints_the_paths(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / 'dqn_cli'
    run.mkdir()
    make_training(run, episodes=5)
    with pytest.raises(SystemExit) as exit_info:
        report.main([str(run), '--ros-args'])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out.split()
    assert out == [str(run / 'report' / 'Result.md'), str(run / 'report' / 'Result.html')]


def test_box_corners_rotate_counter_clockwise() -> None:
    corners = plots.box_corners(0.3, -0.2, math.pi / 2, 0.2, 0.05)
    expected = [[0.25, 0.0], [0.25, -0.4], [0.35, -0.4], [0.35, 0.0]]
    np.testing.assert_allclose(corners, expected, atol=1e-12)


def test_trajectory_draws_the_rotated_obstacle_in_place() -> None:
    fig, ax = plt.subplots()
    try:
        plots.draw_trajectory(ax, make_trace('dqn_heldout', 201, 'success', 5), ARENA)
        patches = {p.get_gid(): p for p in ax.patches}
        box = patches['obstacle_0']
        outline = box.get_path().transformed(box.get_patch_transform())
        yaw = math.pi / 6
        along = (0.3 + 0.18 * math.cos(yaw), -0.2 + 0.18 * math.sin(yaw))  # on the local x axis
        assert outline.contains_point(along)
        assert not outline.contains_point((0.3 + 0.18, -0.2))  # the unrotated box's end
        assert not outline.contains_point((0.3 + 0.18 * math.cos(yaw),
                                           -0.2 - 0.18 * math.sin(yaw)))  # rotated the wrong way
        cylinder = patches['obstacle_2']
        assert cylinder.center == (-0.5, 0.5) and cylinder.radius == pytest.approx(0.08)
        assert patches['goal'].center == (0.5, 0.4)
        assert patches['goal_radius'].radius == pytest.approx(0.1)
        assert patches['final_pose'].center == pytest.approx((0.5, 0.4))
        assert 'success' in ax.get_title()
    finally:
        plt.close(fig)


def test_read_monitor_handles_resumed_files(tmp_path: Path) -> None:
    path = tmp_path / 'monitor.csv'
    path.write_text('#{"t_start": 1.0}\nr,l,t,is_success,event\n1.0,10,1.0,False,none\n'
                    '2.5,20,2.0,True,goal\nr,l,t,is_success,event\n-1.0,5,0.5,False,collision\n')
    data = plots.monitor_arrays(path)
    np.testing.assert_array_equal(data['steps'], [10, 30, 35])
    np.testing.assert_array_equal(data['is_success'], [0, 1, 0])
    assert list(data['event']) == ['none', 'goal', 'collision']
    np.testing.assert_allclose(plots.rolling_mean(np.array([1.0, 3.0, 5.0]), 2), [1, 2, 4])


def test_contact_sheet_frames_and_labels(tmp_path: Path) -> None:
    assert plots.frame_indices(100)[:2] == [0, 5]
    assert plots.frame_indices(100)[-1] == 99 and len(plots.frame_indices(100)) <= 24
    assert plots.frame_indices(3) == [0, 1, 2]
    labels = plots.frame_labels(make_trace('dqn_train', 101, 'collision', 3)['steps'])
    assert labels == ['reset', 'step 1 fwd', 'step 2 fwd', 'step 3 fwd collision']
    frames = np.zeros((4, 3, 84, 84), dtype=np.uint8)
    frames[:, 1] = 200  # green
    out = plots.contact_sheet(frames, tmp_path / 'sheet.png', labels=labels)
    assert out.read_bytes().startswith(PNG_MAGIC)
    with pytest.raises(ValueError):
        plots.contact_sheet(np.zeros((84, 84, 3), dtype=np.uint8), tmp_path / 'bad.png')


def test_malformed_inputs_are_reported_not_fatal(tmp_path: Path) -> None:
    run = tmp_path / 'dqn_broken'
    run.mkdir()
    make_training(run, episodes=5)
    (run / 'validation.json').write_text('[{"name": ')
    write_json(run / 'eval' / 'results.json', {'arena': ARENA, 'sets': [{'name': 'dqn_heldout'}]})
    text = run_report.write_report(run).read_text()
    assert '**Unreadable input:** `validation.json` could not be read' in text
    assert '## 4. Evaluation' in text and '## 8. Reproduce' in text


def test_the_learner_and_its_defaults_read_the_same_in_yaml_config_and_report(
        tmp_path: Path) -> None:
    import dataclasses

    import yaml

    from nav_gym.training.config import TrainConfig
    defaults = dataclasses.asdict(TrainConfig())
    shipped = yaml.safe_load((REPO / 'config' / 'train.yaml').read_text())
    make_training(tmp_path)
    summary = json.loads((tmp_path / 'summary.json').read_text())
    write_json(tmp_path / 'summary.json', {**summary, 'config': defaults})  # a run of today
    text = run_report.write_report(tmp_path).read_text()
    assert f'**Learner:** {TrainConfig().learner().describe()}, `CnnPolicy`.' in text
    for key in run_report.HYPERPARAMETERS:
        value = json.dumps(defaults[key]) if isinstance(defaults[key], dict) else defaults[key]
        # the file's max_episode_steps is 0, the world's limit: 100 in arena.xml
        assert shipped[key] == (0 if key == 'max_episode_steps' else defaults[key]), key
        assert f'| {key} | {value} |' in text, key


def test_a_run_from_before_double_dqn_is_reported_as_sb3_dqn(tmp_path: Path) -> None:
    make_training(tmp_path)  # its config names no double_q: it trained SB3's DQN
    text = run_report.write_report(tmp_path).read_text()
    assert '**Learner:** DQN (SB3), `CnnPolicy`.' in text and '| double_q | False |' in text
