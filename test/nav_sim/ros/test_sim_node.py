"""The nav_sim node as a separate process, started the way ``ros2 run`` starts it."""

from __future__ import annotations

import math
import signal
import subprocess
from collections.abc import Iterator

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo

from helpers import interrupt, wait_until
from nav_sim.core.config import SimConfig
from nav_sim.errors import ScenarioError
from nav_sim.paths import executable_path
from nav_sim.ros import qos
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import ros_args

CFG = SimConfig()
PERIOD_NS = CFG.action_repeat * round(CFG.sim_dt * 1e9)
#: qos.OBSERVATION with room for every message between two looks
EVERY = QoSProfile(depth=100, reliability=qos.OBSERVATION.reliability,
                   durability=qos.OBSERVATION.durability)


def start_node(namespace: str, **params: object) -> subprocess.Popen:
    executable = executable_path('nav_sim', 'sim_node')
    return subprocess.Popen([str(executable), *ros_args(namespace, params)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.fixture
def node(namespace) -> Iterator[tuple[subprocess.Popen, SimClient]]:
    process = start_node(namespace)
    client = SimClient(namespace, timeout=15.0)
    try:
        client.wait_for_sim(30.0)
        yield process, client
    finally:
        client.close()
        if process.poll() is None:
            interrupt(process)


def collect(client: SimClient, msg_type: type, topic: str, profile=qos.OBSERVATION) -> list:
    got: list = []
    client.node.create_subscription(msg_type, topic, got.append, profile)
    return got


def test_publishes_every_topic_with_one_stamp_per_period(node):
    _, client = node
    odom = collect(client, Odometry, 'odom')
    info = collect(client, CameraInfo, 'camera/camera_info')
    clock = collect(client, Clock, '/clock', qos.CLOCK)
    goal = collect(client, PoseStamped, 'goal_pose', qos.LATCHED)
    assert client.spin_until(lambda: goal, 10.0), 'latched goal_pose not delivered'
    # wait until the sim has discovered the new subscriptions, then drive one period
    frame, scenario = client.reset(seed=101, split='train')

    def step_reaches_every_subscription() -> bool:
        nonlocal frame
        frame = client.step(0.0, 0.0, frame)
        return client.spin_until(lambda: odom and info and clock, 0.2)

    wait_until(step_reaches_every_subscription, 10.0, 'odom, camera_info and /clock',
               interval=0)
    frame = client.step(0.12, 0.0, frame)
    assert client.spin_until(lambda: odom[-1].header.stamp == frame.image.header.stamp
                             and info[-1].header.stamp == frame.image.header.stamp
                             and clock[-1].clock == frame.image.header.stamp, 5.0)
    assert frame.image.encoding == 'rgb8'
    assert (frame.image.width, frame.image.height) == (CFG.camera_width, CFG.camera_height)
    assert len(frame.image.data) == CFG.camera_width * CFG.camera_height * 3
    assert info[-1].k[0] > 0 and info[-1].header.frame_id == 'camera_optical_frame'
    assert odom[-1].pose.pose.position.x == pytest.approx(frame.pose[0])
    assert odom[-1].twist.twist.linear.x == pytest.approx(0.12)
    assert (goal[-1].pose.position.x, goal[-1].pose.position.y) == pytest.approx(
        scenario['goal'], abs=1e-4)


def stamp_ns(msg: object) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_lockstep_one_command_one_observation(node):
    _, client = node
    events = collect(client, DiagnosticArray, 'episode_event', EVERY)  # all, in order
    frame = scenario = None

    def reset_reaches_events() -> bool:  # the sim matches a new subscription a moment later
        nonlocal frame, scenario
        frame, scenario = client.reset(seed=102, split='train')
        return client.spin_until(lambda: any(stamp_ns(e) == frame.stamp_ns for e in events),
                                 0.2)

    wait_until(reset_reaches_events, 10.0, 'a reset on a new episode_event subscription',
               interval=0)
    assert frame.event['event'] == 'reset' and frame.event['episode_step'] == 0
    assert frame.stamp_ns == scenario['stamp_ns']
    stamps = [frame.stamp_ns]
    for _ in range(20):
        frame = client.step(0.0, 1.0, frame)  # turning in place never ends the episode
        stamps.append(frame.stamp_ns)
    assert [b - a for a, b in zip(stamps, stamps[1:], strict=False)] == [PERIOD_NS] * 20
    assert frame.event['episode_step'] == 20
    assert frame.pose[2] == pytest.approx(
        math.remainder(scenario['start'][2] + 20 * 1.0 * CFG.ctrl_dt, 2 * math.pi), abs=1e-3)
    # nothing else arrives without a command
    before = client._latest
    client.spin_until(lambda: client._latest is not before, 0.5)
    assert client._latest is before
    # not even late: one topic keeps its order, so had the sim published anything in that
    # half second, it would come between the last step's event and the next command's
    last = frame
    frame = client.step(0.0, 1.0, frame)
    assert client.spin_until(lambda: stamp_ns(events[-1]) == frame.stamp_ns, 5.0)
    assert [stamp_ns(e) for e in events if stamp_ns(e) >= last.stamp_ns] == [
        last.stamp_ns, frame.stamp_ns]
    assert frame.stamp_ns - last.stamp_ns == PERIOD_NS


def test_reset_reports_the_scenario_and_is_reproducible(node):
    _, client = node
    first, a = client.reset(seed=207, split='heldout')
    client.step(0.12, 0.0, first)
    again, b = client.reset(seed=207, split='heldout')
    for key in ('seed', 'split', 'layout', 'start', 'goal', 'initial_distance', 'obstacles'):
        assert a[key] == b[key]
    assert a['split'] == 'heldout' and a['seed'] == 207
    assert bytes(first.image.data) == bytes(again.image.data)
    assert b['stamp_ns'] > a['stamp_ns']


def test_parameters_are_validated(node):
    _, client = node
    with pytest.raises(ScenarioError, match='unknown split'):
        client.set_parameters(split='validation')
    with pytest.raises(ScenarioError, match='seed'):
        client.set_parameters(seed=-3)
    with pytest.raises(ScenarioError):
        client.set_parameters(action_repeat=3)  # read-only after start
    client.set_parameters(seed=5, split='heldout')
    _, scenario = client.reset()
    assert (scenario['seed'], scenario['split']) == (5, 'heldout')


def test_bad_velocities_are_contained(node):
    process, client = node
    frame, _ = client.reset(seed=103)
    frame = client.step(float('nan'), 0.0, frame)
    assert frame.event['wheel_left'] == frame.event['wheel_right'] == 0.0
    frame = client.step(0.0, float('inf'), frame)
    assert frame.event['wheel_left'] == frame.event['wheel_right'] == 0.0
    frame = client.step(1e9, 0.0, frame)
    assert frame.event['wheel_left'] == pytest.approx(CFG.max_wheel_speed)
    assert math.isfinite(frame.pose[0])
    for linear, angular in ((1e308, 0.0), (-1.7e308, 1.4e308)):  # overflowed to NaN before
        frame = client.step(linear, angular, frame)
        wheels = (frame.event['wheel_left'], frame.event['wheel_right'])
        assert max(abs(w) for w in wheels) == pytest.approx(CFG.max_wheel_speed)
        assert all(math.isfinite(v) for v in (*frame.pose, frame.event['distance']))
    stopped = client.stop()
    assert stopped == [0.0, 0.0]
    assert process.poll() is None
    code, output = interrupt(process)
    assert code == 0, output
    assert 'Traceback' not in output
    assert 'non-finite velocity command' in output and 'exceeds the wheel limit' in output


def test_unknown_split_at_start_makes_reset_fail_clearly(namespace):
    process = start_node(namespace, split='validation')
    try:
        with SimClient(namespace, timeout=15.0) as client:
            client.wait_for_sim(30.0)
            response = client._call(client.cli_reset, __import__('std_srvs.srv').srv.Trigger
                                    .Request(), 'reset')
            assert not response.success
            assert 'unknown split' in response.message
            client.set_parameters(split='train')
            _, scenario = client.reset()
            assert scenario['split'] == 'train'
    finally:
        code, output = interrupt(process)
    assert code == 0 and 'Traceback' not in output


def test_realtime_mode_runs_without_commands_and_follows_cmd_vel(namespace):
    process = start_node(namespace, mode='realtime', realtime_rate=4.0)
    try:
        with SimClient(namespace, timeout=15.0) as client:
            client.wait_for_sim(30.0)
            frame, scenario = client.reset(seed=104)
            assert client.spin_until(lambda: client._latest.period >= frame.period + 5, 5.0)
            assert client._latest.pose == pytest.approx(frame.pose, abs=1e-9)  # no cmd: still
            twist = Twist()
            twist.angular.z = 1.0

            def turning() -> bool:
                client.pub_cmd.publish(twist)
                return client.spin_until(
                    lambda: client._latest.twist[1] == pytest.approx(1.0), 0.05)

            wait_until(turning, 5.0, 'the realtime sim turning at the commanded rate',
                       interval=0)
            assert client._latest.twist[1] == pytest.approx(1.0)
    finally:
        code, output = interrupt(process)
    assert code == 0 and 'Traceback' not in output


def test_sigterm_also_exits_cleanly(namespace):
    process = start_node(namespace)
    with SimClient(namespace, timeout=15.0) as client:
        client.wait_for_sim(30.0)
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=15)
    assert process.returncode == 0, err
    assert 'Traceback' not in err
