"""Test rollout videos: decoded frames, what they show, and the report's links and players."""

from __future__ import annotations

import base64
import json
import re
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from test_report import ARENA, make_evaluation, make_trace, make_training, write_json

from nav_eval.reporting import format as report_format
from nav_eval.reporting import run_inputs, run_report
from nav_eval.reporting import videos as video

STEPS = 12


def solid_frames(count: int) -> np.ndarray:
    """Observations (count, 3, 84, 84), each one flat colour that changes with the step."""
    frames = np.zeros((count, 3, 84, 84), dtype=np.uint8)
    frames[:, 0] = np.linspace(20, 230, count, dtype=np.uint8)[:, None, None]
    frames[:, 1] = 90
    frames[:, 2] = 160
    return frames


def decode(path: Path) -> np.ndarray:
    return iio.imread(path, plugin='FFMPEG', index=None)


def camera_region(frame: np.ndarray) -> np.ndarray:
    rows = slice(video.HEADER + video.MARGIN, video.HEADER + video.MARGIN + video.SIDE)
    return frame[rows, video.MARGIN:video.MARGIN + video.SIDE]


def arena_region(frame: np.ndarray) -> np.ndarray:
    return frame[video.HEADER:, 2 * video.MARGIN + video.SIDE:]


@pytest.fixture(scope='module')
def episode_video(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    trace = make_trace('dqn_heldout', 202, 'collision', STEPS)
    frames = solid_frames(STEPS + 1)
    out = video.write_video(trace, frames, ARENA, tmp_path_factory.mktemp('video') / 'v.mp4')
    return out, frames


def test_video_decodes_to_one_frame_per_observation(episode_video) -> None:
    path, frames = episode_video
    decoded = decode(path)
    assert decoded.shape == (STEPS + 1, video.HEIGHT, video.WIDTH, 3)
    meta = iio.immeta(path, plugin='FFMPEG')
    assert meta['codec'] == 'h264' and meta['fps'] == pytest.approx(video.FPS)
    assert not list(path.parent.glob('.*partial*'))  # written atomically


def test_each_frame_shows_its_observation_in_order(episode_video) -> None:
    path, frames = episode_video
    decoded = decode(path)
    for index, frame in enumerate(decoded):
        shown = camera_region(frame)[8:-8, 8:-8].reshape(-1, 3).mean(axis=0)
        np.testing.assert_allclose(shown, frames[index, :, 0, 0], atol=6, err_msg=str(index))


def test_the_top_down_view_draws_the_path_so_far(episode_video) -> None:
    decoded = decode(episode_video[0]).astype(int)
    path_colour = np.array([31, 119, 180])  # tab:blue

    def path_pixels(index: int) -> np.ndarray:
        distance = np.abs(arena_region(decoded[index]) - path_colour).sum(axis=2)
        return np.argwhere(distance < 40)

    first, middle, last = (path_pixels(i) for i in (0, STEPS // 2, STEPS))
    assert len(first) < 20 < len(middle) < len(last)
    # the path grows from the start (lower left) towards the goal (upper right)
    assert last[:, 1].max() > middle[:, 1].max() and last[:, 0].min() < middle[:, 0].min()


def test_frame_labels_name_step_action_reward_and_outcome() -> None:
    texts = video.frame_texts(make_trace('dqn_train', 103, 'collision', 3))
    assert len(texts) == 4
    assert texts[0] == 'reset: distance 1.49 m'
    assert texts[1].startswith('step 1 fwd: reward +0.010, return +0.010, distance ')
    assert texts[3].startswith('step 3 fwd collision: reward +0.010, return +0.030')
    assert texts[3].endswith('| episode over: collision')


def test_frames_that_do_not_match_the_trace_are_an_error(tmp_path: Path) -> None:
    trace = make_trace('dqn_train', 101, 'success', 4)
    with pytest.raises(ValueError, match='4 frames for 4 steps'):
        video.write_video(trace, solid_frames(4), ARENA, tmp_path / 'x.mp4')
    assert not list(tmp_path.iterdir())  # no partial file left behind


def test_observations_of_other_sizes_fill_the_panel_in_whole_pixels(tmp_path: Path) -> None:
    assert video.camera_scale(84, 84) == 4 and video.camera_scale(96, 128) == 2
    trace = make_trace('dqn_train', 101, 'success', 2)
    frames = np.full((3, 3, 96, 128), 200, dtype=np.uint8)
    decoded = decode(video.write_video(trace, frames, ARENA, tmp_path / 'native.mp4'))
    assert decoded.shape == (3, video.HEIGHT, video.WIDTH, 3)
    with pytest.raises(ValueError, match='larger than the video panel'):
        video.write_video(trace, np.zeros((3, 3, 400, 400), np.uint8), ARENA, tmp_path / 'x.mp4')


@pytest.fixture(scope='module')
def reported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp('runs') / 'dqn_video'
    run.mkdir()
    make_training(run)
    make_evaluation(run)
    return run_report.write_report(run)


def test_report_links_a_video_of_each_representative_episode(reported: Path) -> None:
    text = reported.read_text()
    section = text.split('## 5.')[1].split('## 6.')[0]
    links = re.findall(r'\[▶ ([^\]]+)\]\((videos/[^)]+\.mp4)\)', section)
    assert links == [
        ('Success: dqn_heldout seed 201 (success, 12 steps)', 'videos/dqn_heldout_seed_201.mp4'),
        ('Failure (diagnosed): dqn_heldout seed 202 (collision, 12 steps)',
         'videos/dqn_heldout_seed_202.mp4')]
    for _, target in links:
        assert decode(reported.parent / target).shape == (13, video.HEIGHT, video.WIDTH, 3)


def test_html_embeds_the_videos_as_players(reported: Path) -> None:
    page = reported.with_suffix('.html').read_text()
    sources = re.findall(r'<video controls preload="metadata" src="data:video/mp4;base64,'
                         r'([^"]+)"', page)
    assert len(sources) == 2
    embedded = base64.b64decode(sources[0])
    assert embedded == (reported.parent / 'videos' / 'dqn_heldout_seed_201.mp4').read_bytes()
    assert 'href="videos/' not in page  # self-contained: nothing refers to the folder
    assert '<br><em>Success: dqn_heldout seed 201 (success, 12 steps)</em>' in page


def test_html_references_a_video_too_large_to_embed(reported: Path, monkeypatch) -> None:
    monkeypatch.setattr(report_format, 'VIDEO_EMBED_LIMIT', 1000)
    page = report_format.to_html(reported.read_text(), reported.parent, 'x')
    assert 'data:video/mp4' not in page
    assert '<video controls preload="metadata" src="videos/dqn_heldout_seed_201.mp4">' in page


def test_the_diagnosed_episode_gets_a_video_when_not_shown_otherwise(tmp_path: Path) -> None:
    run = tmp_path / 'dqn_diag'
    run.mkdir()
    make_training(run)
    make_evaluation(run)
    diagnosis = json.loads((run / 'eval' / 'diagnosis.json').read_text())
    # nav-eval-diagnose --set dqn_train --seed 101: an episode the report shows nowhere else
    write_json(run / 'eval' / 'diagnosis.json', {**diagnosis, 'set': 'dqn_train', 'seed': 101,
                                                 'outcome': 'success'})
    captions = [c for c, _, _ in run_inputs.video_episodes(run_inputs.load_run(run))]
    assert captions == ['Success: dqn_heldout seed 201 (success, 12 steps)',
                        'Failure: dqn_heldout seed 202 (collision, 12 steps)',
                        'Diagnosed: dqn_train seed 101 (success, 12 steps)']
    # before any diagnosis: the episode nav-eval-diagnose would pick
    (run / 'eval' / 'diagnosis.json').unlink()
    captions = [c for c, _, _ in run_inputs.video_episodes(run_inputs.load_run(run))]
    assert captions[1] == 'Failure (to diagnose): dqn_heldout seed 202 (collision, 12 steps)'


def test_evaluate_video_flag_with_out_elsewhere_is_a_clear_error(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, '-m', 'nav_eval.evaluate', str(tmp_path), '--video',
                             '--out', str(tmp_path / 'elsewhere')],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert 'Traceback' not in result.stderr
    assert '--video reads the evaluation' in result.stderr


def test_evaluate_writes_a_video_of_a_real_episode(tmp_path: Path, spaces_only) -> None:
    """A tiny DQN through the real graph: the video has one frame per stored observation."""
    from stable_baselines3 import DQN

    from nav_gym.training.config import TrainConfig
    (tmp_path / 'config.yaml').write_text(TrainConfig(max_episode_steps=8).to_yaml())
    model = DQN('CnnPolicy', spaces_only(), buffer_size=64, learning_starts=16, batch_size=8,
                seed=3, device='cpu')
    model.save(tmp_path / 'final_model.zip')
    result = subprocess.run([sys.executable, '-m', 'nav_eval.evaluate', str(tmp_path), '--sets',
                             'dqn_heldout', '--heldout-seeds', '201', '--no-record', '--video'],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    trace = json.loads((tmp_path / 'eval' / 'traces' / 'dqn_heldout' / 'seed_201.json')
                       .read_text())
    with np.load(tmp_path / 'eval' / 'traces' / 'dqn_heldout' / 'seed_201_frames.npz') as data:
        observations = data['obs']
    path = tmp_path / 'eval' / 'videos' / 'dqn_heldout_seed_201.mp4'
    assert f'video {path}' in result.stdout
    decoded = decode(path)
    assert decoded.shape == (len(trace['steps']) + 1, video.HEIGHT, video.WIDTH, 3)
    for index in (0, len(decoded) - 1):
        expected = observations[index].transpose(1, 2, 0).repeat(4, 0).repeat(4, 1).astype(int)
        assert np.abs(camera_region(decoded[index]).astype(int) - expected).mean() < 8
