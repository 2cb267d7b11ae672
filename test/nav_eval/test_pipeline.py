"""The main job end to end: validate -> train -> evaluate -> diagnose -> report.

The default run uses a few hundred steps; the full workshop protocol (50k steps) and its
learning target are behind the ``slow`` marker (``make test-slow``).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from nav_eval.reporting.run_report import SECTIONS
from nav_sim.paths import executable_path

TINY = ['--total-timesteps', '200', '--learning-starts', '100', '--checkpoint-freq', '100',
        '--buffer-size', '500', '--max-episode-steps', '12']


def pipeline(tmp_path, *args: str, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'nav_eval.pipeline', '--runs-dir',
                           str(tmp_path), '--run-name', 'run', *args],
                          capture_output=True, text=True, timeout=timeout)


def test_pipeline_runs_every_stage_and_writes_the_report(tmp_path):
    result = pipeline(tmp_path, *TINY, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    for number in range(1, 6):
        assert f'[{number}/5]' in result.stdout
    run = tmp_path / 'run'
    # a finished run keeps no replay buffer (only --resume needs one)
    assert not (run / 'checkpoints' / 'replay_buffer.pkl').exists()
    checks = json.loads((run / 'validation.json').read_text())
    assert len(checks) == 12 and all(c['passed'] for c in checks)
    results = json.loads((run / 'eval' / 'results.json').read_text())
    assert [s['name'] for s in results['sets']] == ['random_train', 'dqn_train', 'dqn_heldout',
                                                    'early_train', 'early_heldout']
    assert all(s['summary']['episodes'] == 10 for s in results['sets'])
    report = (run / 'report' / 'Result.md').read_text()
    for heading in SECTIONS:
        assert heading in report
    assert 'Missing' not in report.split(SECTIONS[6])[0]  # every evidence section is filled
    assert (run / 'report' / 'Result.html').stat().st_size > 50_000
    assert sorted(p.name for p in (run / 'eval' / 'bags').iterdir()) == sorted(
        s['name'] for s in results['sets'])


@pytest.mark.slow
def test_full_protocol_reaches_the_learning_target(tmp_path):
    """Workshop settings, 50k steps: held-out success >= 80%, collisions <= 10%, random < 15%."""
    result = pipeline(tmp_path, timeout=5400)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    sets = {s['name']: s['summary'] for s in json.loads(
        (tmp_path / 'run' / 'eval' / 'results.json').read_text())['sets']}
    print(json.dumps(sets, indent=1))
    assert sets['random_train']['success_rate'] < 0.15
    assert sets['dqn_heldout']['success_rate'] >= 0.8
    assert sets['dqn_heldout']['collision_rate'] <= 0.1


@pytest.mark.parametrize('executable', ['evaluate', 'record', 'report', 'diagnose'])
def test_ros2_run_finds_every_nav_eval_executable(executable):
    """As ros2run resolves it: <prefix of nav_eval>/lib/nav_eval/<executable>."""
    import os

    path = executable_path('nav_eval', executable)
    assert path.is_file() and os.access(path, os.X_OK)
    result = subprocess.run([str(path), '--help', '--ros-args', '-r', '__ns:=/x'],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert 'usage:' in result.stdout
