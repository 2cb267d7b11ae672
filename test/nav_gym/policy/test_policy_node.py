"""The policy node as a separate process, started the way ``ros2 run nav_gym policy`` starts it.

A test node publishes images (rendered by the sim core, in every encoding the node takes) and
listens to what the policy node sends: ``cmd_vel``, ``policy/decision`` and
``policy/observation``.
"""

from __future__ import annotations

import itertools
import math
import signal
import subprocess
import time
from collections.abc import Iterator

import cv2
import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import Image
from std_srvs.srv import Trigger

from helpers import interrupt, make_tiny_run
from nav_gym.env.observation import image_msg_to_observation
from nav_sim import interface
from nav_sim.core.config import SimConfig
from nav_sim.core.kinematics import twist_to_wheels
from nav_sim.core.sim import NavSim
from nav_sim.paths import executable_path
from nav_sim.ros import messages as ros_msgs
from nav_sim.ros import qos
from policy_graph import Graph

#: how each encoding's bytes are made from RGB (mono8: from the RGB's grey)
ENCODINGS = {'rgb8': None, 'bgr8': cv2.COLOR_RGB2BGR, 'rgba8': cv2.COLOR_RGB2RGBA,
             'bgra8': cv2.COLOR_RGB2BGRA, 'mono8': cv2.COLOR_RGB2GRAY}


def start_policy(*ros_args: str) -> subprocess.Popen:
    executable = executable_path('nav_gym', 'policy')
    return subprocess.Popen([str(executable), '--ros-args', *ros_args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.fixture
def graph(namespace) -> Iterator[Graph]:
    g = Graph(namespace)
    yield g
    g.close()


@pytest.fixture(scope='module')
def frames() -> list[np.ndarray]:
    """Three rendered camera frames of one scenario (native 128x96 RGB)."""
    sim = NavSim(SimConfig())
    try:
        sim.reset(101, 'train')
        out = [sim.render()]
        for _ in range(2):
            sim.step(twist_to_wheels(0.12, 0.75, sim.config))
            out.append(sim.render())
        return out
    finally:
        sim.close()


def encoded(rgb: np.ndarray, encoding: str, stamp_ns: int, pad: int = 0) -> Image:
    """Return an Image of ``rgb`` in ``encoding`` with ``pad`` bytes of garbage per row."""
    conversion = ENCODINGS[encoding]
    pixels = rgb if conversion is None else cv2.cvtColor(rgb, conversion)
    rows = pixels.reshape(rgb.shape[0], -1)
    padded = np.full((rows.shape[0], rows.shape[1] + pad), 0xAB, np.uint8)
    padded[:, :rows.shape[1]] = rows
    msg = Image(height=rgb.shape[0], width=rgb.shape[1], encoding=encoding,
                step=padded.shape[1])
    msg.data = padded.tobytes()
    msg.header.stamp = ros_msgs.stamp_from_ns(stamp_ns)
    msg.header.frame_id = 'camera_optical_frame'
    return msg


def output(process: subprocess.Popen) -> str:
    return interrupt(process)[1]


def test_the_observation_is_byte_identical_to_the_envs_in_every_encoding_size_and_padding(
        graph, namespace, frames):
    process = start_policy('-r', f'__ns:={namespace}', '-p', 'policy:=servo',
                           '-p', 'period:=0.05')
    try:
        graph.connected(details=lambda: output(process))
        stamp = 1_000_000_000
        cases = [(rgb, encoding, pad) for rgb in frames for encoding in ENCODINGS
                 for pad in (0, 5)]
        cases.append((cv2.resize(frames[0], (77, 53)), 'rgb8', 3))   # an odd size, padded
        cases.append((cv2.resize(frames[1], (640, 480)), 'bgra8', 0))  # larger than native
        env_rgb8 = {}
        for rgb, encoding, pad in cases:
            stamp += 1_000_000
            msg = encoded(rgb, encoding, stamp, pad)

            got = graph.stream(msg, lambda s=stamp: next(
                (o for o in graph.observations if ros_msgs.stamp_to_ns(o.header.stamp) == s),
                None), 10.0, f'the observation of a {encoding} image (pad {pad})')
            node_obs = np.frombuffer(got.data, np.uint8).reshape(84, 84, 3).transpose(2, 0, 1)
            env_obs, _ = image_msg_to_observation(msg)  # what the env makes of the same image
            assert np.array_equal(node_obs, env_obs), (encoding, pad, rgb.shape)
            if encoding != 'mono8':  # every colour encoding of a frame gives one observation
                assert np.array_equal(env_rgb8.setdefault(id(rgb), node_obs), node_obs)
    finally:
        code, text = interrupt(process)
    assert code == 0 and 'Traceback' not in text, text


def test_a_stale_camera_stops_the_robot_and_says_so_once(graph, namespace, frames):
    process = start_policy('-r', f'__ns:={namespace}', '-p', 'policy:=servo',
                           '-p', 'period:=0.05', '-p', 'image_timeout:=0.4')
    try:
        graph.connected(details=lambda: output(process))
        assert graph.decision(graph.decisions[-1])['action'] == -1  # no image yet: stop
        graph.stream(encoded(frames[0], 'rgb8', 5_000_000_000),
                     lambda: graph.decision(graph.decisions[-1])['action'] >= 0, 10.0,
                     'a decision on the image')
        moving = graph.twists[-1]
        assert (moving.linear.x, moving.angular.z) != (0.0, 0.0)
        started = time.monotonic()
        graph.spin_until(lambda: graph.decision(graph.decisions[-1])['action'] == -1, 10.0,
                         'a stop once the image is stale')
        assert time.monotonic() - started < 1.5
        stopped = graph.twists[-1]
        assert (stopped.linear.x, stopped.angular.z) == (0.0, 0.0)
        latest = graph.decision(graph.decisions[-1])
        assert latest['image_age_ms'] > 400.0 and math.isnan(latest['q_left'])
    finally:
        code, text = interrupt(process)
    assert code == 0, text
    assert text.count('no image on') == 1, text  # at the start
    assert text.count('no image newer than 0.400 s on') == 1, text  # once stale


def test_an_unsupported_encoding_is_one_error_logged_once(graph, namespace, frames):
    process = start_policy('-r', f'__ns:={namespace}', '-p', 'policy:=servo',
                           '-p', 'period:=0.05')
    try:
        graph.connected(details=lambda: output(process))
        bad = encoded(frames[0], 'rgb8', 9_000_000_000)
        bad.encoding = '16UC1'
        for _ in range(3):
            graph.publish(bad)
            graph.decisions.clear()
            graph.spin_until(lambda: len(graph.decisions) > 5, 10.0, 'decisions')
        assert graph.decision(graph.decisions[-1])['action'] == -1
        assert (graph.twists[-1].linear.x, graph.twists[-1].angular.z) == (0.0, 0.0)
    finally:
        code, text = interrupt(process)
    assert code == 0, text
    assert text.count("unsupported image encoding '16UC1'") == 1, text


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_sigint_and_sigterm_leave_a_zero_twist_as_the_last_command(graph, namespace, frames,
                                                                   sig):
    process = start_policy('-r', f'__ns:={namespace}', '-p', 'policy:=servo',
                           '-p', 'period:=0.05')
    try:
        graph.connected(details=lambda: output(process))
        graph.stream(encoded(frames[0], 'rgb8', 3_000_000_000),
                     lambda: graph.twists and graph.twists[-1].angular.z != 0.0, 10.0,
                     'a moving command')
        process.send_signal(sig)
        process.wait(15)
        graph.spin_until(lambda: graph.twists[-1].angular.z == 0.0, 5.0, 'the zero Twist')
    finally:
        code, text = interrupt(process)
    last = graph.twists[-1]
    assert (last.linear.x, last.angular.z) == (0.0, 0.0)
    assert code == 0 and 'Traceback' not in text, text


@pytest.mark.parametrize(('args', 'code', 'expected'), [
    (['-p', 'model:=/no/such/run'], 1, 'policy_node: model /no/such/run not found'),
    (['-p', 'period:=abc', '-p', 'policy:=servo'], 2,
     "policy_node: invalid configuration: parameter period takes a number, got 'abc'"),
    (['-p', 'period:=1', '-p', 'policy:=servo'], 2,
     'policy_node: invalid configuration: parameter period takes a double: write 1.0, not 1'),
    (['-p', 'policy:=ppo'], 2, 'policy_node: invalid configuration: policy must be one of'),
    (['-p', 'image_timeout:=-1.0', '-p', 'policy:=servo'], 2,
     'policy_node: invalid configuration: image_timeout must be >= 0, got -1.0'),
])
def test_bad_models_and_parameters_are_one_line_and_a_non_zero_exit(namespace, args, code,
                                                                     expected):
    process = start_policy('-r', f'__ns:={namespace}', *args)
    out, err = process.communicate(timeout=120)
    out += err
    assert process.returncode == code, out
    lines = out.splitlines()
    assert len(lines) == 1 and lines[0].startswith(expected), out


def test_a_corrupt_model_is_one_line(tmp_path, namespace):
    bad = tmp_path / 'model.zip'
    bad.write_bytes(b'PK not really')
    process = start_policy('-r', f'__ns:={namespace}', '-p', f'model:={bad}')
    out, err = process.communicate(timeout=120)
    out += err
    assert process.returncode == 1 and len(out.splitlines()) == 1, out
    assert out.startswith(f'policy_node: cannot read the model {bad}'), out


def test_remapping_a_params_file_and_runtime_parameters(tmp_path, namespace, frames):
    params = tmp_path / 'policy.yaml'
    params.write_text('/**:\n  ros__parameters:\n    policy: servo\n    period: 0.05\n'
                      '    perido: 1.0\n')
    graph = Graph(namespace, image_topic=f'{namespace}/robot/camera/image')
    process = start_policy('-r', f'__ns:={namespace}', '--params-file', str(params),
                           '-r', f'camera/image_raw:={namespace}/robot/camera/image')
    try:
        graph.connected(details=lambda: output(process))
        graph.stream(encoded(frames[0], 'rgb8', 2_000_000_000),
                     lambda: graph.decision(graph.decisions[-1])['action'] >= 0, 10.0,
                     'a decision on the remapped camera')
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter
        client = graph.node.create_client(SetParameters,
                                          f'{namespace}/policy_node/set_parameters')
        assert client.wait_for_service(timeout_sec=10.0)

        def set_values(**values):
            request = SetParameters.Request(parameters=[
                Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
            future = client.call_async(request)
            graph.spin_until(future.done, 10.0, 'set_parameters')
            return future.result().results

        refused = set_values(period=-0.5)[0]
        assert not refused.successful and 'period must be >= 0, got -0.5' in refused.reason
        assert not set_values(period='fast')[0].successful
        assert not set_values(model='/elsewhere')[0].successful  # read-only
        assert set_values(image_timeout=2)[0].successful  # an integer converts to a double
    finally:
        code, text = interrupt(process)
        graph.close()
    assert code == 0, text
    assert "unknown parameter 'perido' ignored (did you mean period?)" in text, text


def test_a_dqn_run_decides_with_its_q_values_and_its_runs_actions(tmp_path, namespace, frames,
                                                                   spaces_only, graph):
    run = make_tiny_run(tmp_path, spaces_only, forward_speed=0.2, turn_rate=1.0)
    process = start_policy('-r', f'__ns:={namespace}', '-p', f'model:={run}',
                           '-p', 'period:=0.05')
    try:
        graph.connected(details=lambda: output(process))
        decision = graph.decision(graph.stream(
            encoded(frames[1], 'bgr8', 4_000_000_000),
            lambda: next((d for d in reversed(graph.decisions)
                          if ros_msgs.stamp_to_ns(d.header.stamp) == 4_000_000_000
                          and graph.decision(d)['action'] >= 0), None),
            20.0, 'a decision on the image'))
        q_values = [decision['q_left'], decision['q_forward'], decision['q_right']]
        assert all(math.isfinite(q) for q in q_values)
        assert decision['action'] == int(np.argmax(q_values))
        twist = {0: (0.03, 1.0), 1: (0.2, 0.0), 2: (0.03, -1.0)}[int(decision['action'])]
        assert (decision['linear'], decision['angular']) == twist
        assert decision['inference_ms'] > 0.0 and decision['image_age_ms'] >= 0.0
    finally:
        code, text = interrupt(process)
    assert code == 0 and 'Traceback' not in text, text
    assert f'from {run}/config.yaml' in text


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')
@pytest.mark.parametrize('source', ['checkpoint', 'onnx'])
def test_a_memory_policy_begins_its_history_at_a_reset_event_the_service_and_a_stale_stop(
        tmp_path, namespace, frames, spaces_only, graph, source):
    """A 2-frame-stack model: the Q-values of image A tell whether A began the history.

    A fresh history stacks A with itself; after B without a new episode it stacks B and A,
    whose Q-values differ (checked first: the probe can see a history that goes on).  The
    same for its checkpoint and its ONNX export.
    """
    run = make_tiny_run(tmp_path, spaces_only, frame_stack=2, previous_action=False)
    if source == 'onnx':
        from nav_gym.policy.export import export_policy
        model = export_policy(run).path
    else:
        model = run
    process = start_policy('-r', f'__ns:={namespace}', '-p', f'model:={model}',
                           '-p', 'period:=0.05', '-p', 'image_timeout:=2.0')
    events = graph.node.create_publisher(DiagnosticArray, interface.EVENT_TOPIC,
                                         qos.OBSERVATION)
    begin = graph.node.create_client(Trigger, interface.POLICY_BEGIN_EPISODE_SERVICE)
    stamps = itertools.count(1)
    image_a, image_b = frames[0], frames[2]

    def q_values(msg) -> tuple[float, ...]:  # noqa: ANN001
        d = graph.decision(msg)
        return d['q_left'], d['q_forward'], d['q_right']

    def decided(rgb: np.ndarray, wanted: tuple[float, ...] | None = None,
                stamp: int | None = None) -> tuple[float, ...]:
        """Show ``rgb``; return the Q-values of the decision on it (``wanted``, once they are).

        A reset event and its frame travel on two topics with one stamp: a decision the node
        made on the frame before it took the event is made again after it, afresh.
        """
        stamp = stamp if stamp is not None else next(stamps) * 1_000_000_000
        graph.publish(encoded(rgb, 'rgb8', stamp))

        def found() -> tuple[float, ...] | None:
            mine = [q_values(d) for d in graph.decisions
                    if ros_msgs.stamp_to_ns(d.header.stamp) == stamp]
            if wanted is None:
                return mine[0] if mine else None
            return wanted if wanted in mine else None
        def last() -> str:
            return f'the last Q-values: {[q_values(d) for d in graph.decisions[-5:]]}'
        return graph.spin_until(found, 20.0, f'a decision on the image stamped {stamp}', last)

    try:
        graph.connected(details=lambda: output(process))
        graph.spin_until(lambda: events.get_subscription_count() > 0
                         and begin.service_is_ready(), 20.0, 'the episode event and service')
        fresh = decided(image_a)  # the node's first episode: A begins the history
        after_b = decided(image_b)
        going_on = decided(image_a)  # no new episode: B and A
        assert going_on != fresh, 'the probe cannot tell a history that goes on'
        assert decided(image_b) == after_b  # B last: A without a new episode is B and A
        # 1. the sim's reset event, stamped as its frame (the image before it is not acted on)
        reset = next(stamps) * 1_000_000_000
        events.publish(ros_msgs.event_msg(ros_msgs.EVENT_RESET, {'seed': 5, 'episode': 2},
                                          ros_msgs.stamp_from_ns(reset)))
        assert decided(image_a, fresh, stamp=reset) == fresh
        assert decided(image_b) == after_b  # and the history goes on within the episode
        # 2. the explicit reset: the policy/begin_episode service
        future = begin.call_async(Trigger.Request())
        graph.spin_until(future.done, 20.0, 'the policy/begin_episode answer')
        assert future.result().success
        assert decided(image_a) == fresh
        assert decided(image_b) == after_b
        # 3. a stale image: the stop, then the next image begins the history
        graph.spin_until(lambda: graph.decision(graph.decisions[-1])['action'] == -1, 20.0,
                         'the stale-image stop')
        assert decided(image_a) == fresh
    finally:
        code, text = interrupt(process)
    assert code == 0 and 'Traceback' not in text, text
