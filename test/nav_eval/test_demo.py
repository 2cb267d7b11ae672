"""``make demo``: the policy node drives a realtime sim through one episode."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from helpers import free_port, make_tiny_run, wait_until
from nav_sim.viz import topics as live_topics
from nav_sim.viz.client import LiveClient

DEMO = str(Path(sys.prefix) / 'bin' / 'visnav-demo')


def test_without_a_model_the_servo_drives_to_the_goal_and_nothing_is_left():
    result = subprocess.run([DEMO, '--rate', '8'], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'the image-only servo' in result.stdout
    assert 'episode over: success' in result.stdout, result.stdout
    assert 'Traceback' not in result.stderr
    ps = subprocess.run(['ps', '-eo', 'args'], capture_output=True, text=True).stdout
    assert not [line for line in ps.splitlines()
                if 'visnav_closed_loop_' in line and 'realtime_rate:=8.0' in line]


def test_a_missing_model_is_one_line():
    result = subprocess.run([DEMO, '--model', '/no/such/run'], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 1
    assert result.stderr.strip() == ('visnav-demo: error: model /no/such/run not found: give a '
                                     'run directory, a checkpoint .zip or an export directory')


def test_an_export_drives_the_demo_on_onnx_runtime(tmp_path, spaces_only):
    run = make_tiny_run(tmp_path, spaces_only)
    from nav_gym.policy.export import export_policy
    export = export_policy(run).path
    result = subprocess.run([DEMO, '--model', str(export), '--rate', '8'], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert f'the model {export}' in result.stdout and 'episode over: ' in result.stdout


def test_the_live_view_shows_the_policys_decisions():
    port = free_port()
    process = subprocess.Popen([DEMO, '--rate', '4', '--live', str(port)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        def viewer() -> LiveClient | None:
            try:
                return LiveClient(port, timeout=2.0)
            except OSError:
                return None

        client = wait_until(viewer, 120.0, 'the demo live view')
        with client:
            assert live_topics.DECISION_TOPIC in client.channels
            client.subscribe([live_topics.DECISION_TOPIC, live_topics.STEP_TOPIC])
            got: dict[str, list] = {}

            def received() -> bool:
                for message in client.receive(0.1):
                    got.setdefault(message.topic, []).append(message.decode())
                return bool(got.get(live_topics.DECISION_TOPIC)) and bool(
                    got.get(live_topics.STEP_TOPIC))

            wait_until(received, 120.0, 'decisions and steps from the live view')
        decision = got[live_topics.DECISION_TOPIC][-1]
        assert list(decision.name)[0] == 'action' and len(decision.position) == 9
        process.wait(timeout=120)
    finally:
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
        out, err = process.communicate()
    assert process.returncode == 0, out + err
