"""BagRecorder and ``nav-eval-record`` against a real sim_node process; bags read back."""

from __future__ import annotations

import importlib.util
import math
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Twist, Vector3
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock

from helpers import wait_until
from nav_eval.errors import RecordingError
from nav_eval.recording.bags import (
    EPISODE_TOPIC,
    PERIOD_TOPICS,
    SIM_TOPICS,
    cdr_stamp_ns,
    episode_events,
    episodes_in_bag,
    read_bag,
)
from nav_eval.recording.recorder import BagRecorder
from nav_eval.recording.session import format_counts
from nav_eval.recording.topics import bag_qos
from nav_gym.cli import strip_ros_args
from nav_sim.ros import qos
from nav_sim.ros.bare import own_node
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import SimProcess

STEPS = 10
MCAP_MAGIC = b'\x89MCAP0\r\n'
#: no reset at start-up: nothing is published before a test drives the sim
QUIET_START = {'publish_clock': True, 'reset_on_start': False}


def header_ns(msg: object) -> int:
    stamp = msg.header.stamp
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def check_metadata(bag: Path, counts: dict[str, int]) -> Path:
    """metadata.yaml agrees with ``counts``; returns the MCAP file, checked for its magic."""
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['storage_identifier'] == 'mcap' and meta['version'] == 9
    listed = {t['topic_metadata']['name']: t['message_count']
              for t in meta['topics_with_message_count']}
    assert listed == counts
    assert meta['message_count'] == sum(counts.values())
    mcap_file = bag / meta['relative_file_paths'][0]
    data = mcap_file.read_bytes()
    assert data.startswith(MCAP_MAGIC) and data.endswith(MCAP_MAGIC)
    return mcap_file


def check_with_mcap_library(mcap_file: Path, counts: dict[str, int]) -> None:
    """Check that the independent ``mcap`` reader sees the same messages (if installed)."""
    if importlib.util.find_spec('mcap') is None:
        return
    from mcap.reader import make_reader

    with mcap_file.open('rb') as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == 'ros2'
        seen = Counter(channel.topic for _, channel, _ in reader.iter_messages())
    assert dict(seen) == {topic: n for topic, n in counts.items() if n}


def warm_up(client: SimClient, recorder: BagRecorder) -> None:
    """Step until a whole control period reaches the recorder.

    The sim can match the recorder's subscriptions a few hundred milliseconds after the
    recorder has matched the sim's publishers; what it publishes in between is lost.
    """
    frame, _ = client.reset(seed=7)

    def whole_period_recorded() -> bool:
        nonlocal frame
        if recorder.wait_for(frame.stamp_ns, 0.1, (*PERIOD_TOPICS, '/clock')):
            return True
        frame = client.step(0.0, 0.0, frame)
        return False

    wait_until(whole_period_recorded, 30.0, 'a whole control period of the sim at the recorder',
               interval=0)


def since(messages: list[tuple[int, object]], start: int, end: float = math.inf
          ) -> list[tuple[int, object]]:
    return [(t, m) for t, m in messages if start <= t <= end]


def check_periods(messages: dict, episode: dict, namespace: str, stamps: list[int]) -> None:
    """One message per control period on every per-period topic, at its sim stamp."""
    all_images = messages[f'{namespace}/camera/image_raw']
    assert all(b[0] > a[0] for a, b in zip(all_images, all_images[1:], strict=False))
    images = episode[f'{namespace}/camera/image_raw']
    assert [t for t, _ in images] == stamps == [header_ns(m) for _, m in images]
    for _, image in images:
        assert (image.width, image.height, image.encoding) == (128, 96, 'rgb8')
        assert image.step == 128 * 3 and len(image.data) == 128 * 96 * 3
    for name in PERIOD_TOPICS[1:]:
        stamped = episode[f'{namespace}/{name}']
        assert [t for t, _ in stamped] == [header_ns(m) for _, m in stamped] == stamps, name
    clock = episode['/clock']
    assert [t for t, _ in clock] == stamps
    assert [m.clock.sec * 1_000_000_000 + m.clock.nanosec for _, m in clock] == stamps


def test_bag_holds_every_topic_of_a_lockstep_episode(tmp_path, namespace):
    bag = tmp_path / 'episode_bag'
    info = {'set': 'smoke', 'policy': 'scripted', 'checkpoint': None, 'seed': 101,
            'split': 'train', 'outcome': 'none', 'length': STEPS, 'return': np.float32(-0.5)}
    with SimProcess(namespace, params=QUIET_START), BagRecorder(bag, namespace) as recorder, \
            SimClient(namespace, timeout=15.0) as client:
        client.wait_for_sim(30.0)
        assert recorder.wait_for_publishers(15.0, (*SIM_TOPICS, '/clock'))
        wait_until(lambda: client.pub_cmd.get_subscription_count() >= 2, 15.0,
                   'cmd_vel matched by the sim and the recorder')
        warm_up(client, recorder)
        frame, scenario = client.reset(seed=101, split='train')
        stamps = [frame.stamp_ns]
        for _ in range(STEPS):
            frame = client.step(0.02, 0.3, frame)  # gentle: no collision in 10 periods
            stamps.append(frame.stamp_ns)
            assert recorder.wait_for(frame.stamp_ns, 5.0)
        assert not recorder.wait_for(frame.stamp_ns + 1, 0.2)  # no frame without a command
        recorder.annotate(info)
        # not even a late one: one topic keeps its order, so a frame the sim had published
        # since would reach the bag before the frame of one more command, the marker
        marker = client.step(0.0, 0.0, frame)
        assert recorder.wait_for(marker.stamp_ns, 5.0, (*PERIOD_TOPICS, '/clock'))
    recorder.close()  # idempotent
    counts = recorder.counts
    mcap_file = check_metadata(bag, counts)
    check_with_mcap_library(mcap_file, counts)
    messages = read_bag(bag)
    assert {topic: len(msgs) for topic, msgs in messages.items()} == counts
    start = stamps[0]
    episode = {topic: since(msgs, start, stamps[-1]) for topic, msgs in messages.items()}

    check_periods(messages, episode, namespace, stamps)
    for topic in [f'{namespace}/{name}' for name in PERIOD_TOPICS] + ['/clock']:
        assert [t for t, _ in since(messages[topic], stamps[-1] + 1)] == [marker.stamp_ns], topic
    # the episode's commands, then the marker's; no other (0.02, 0.3) command anywhere (the
    # warm-up sent zeros).  A command has no stamp: the recorder gives it the newest sim time it
    # has met, normally the frame it answers, an earlier one when it overtakes that frame on
    # the way (two publishers, no order between them), so its stamp cannot pick it out
    commands = [(m.linear.x, m.angular.z) for _, m in messages[f'{namespace}/cmd_vel']]
    assert commands[-(STEPS + 1):] == [(0.02, 0.3)] * STEPS + [(0.0, 0.0)]
    assert commands.count((0.02, 0.3)) == STEPS
    times = [t for t, _ in messages[f'{namespace}/cmd_vel']]
    sim_times = {t for topic, msgs in messages.items() for t, _ in msgs
                 if topic not in (f'{namespace}/cmd_vel', EPISODE_TOPIC)}
    assert set(times) <= sim_times and times == sorted(times)

    goal = episode[f'{namespace}/goal_pose'][-1][1].pose.position
    assert (goal.x, goal.y) == pytest.approx(scenario['goal'], abs=1e-4)
    events = [e for t, e in episode_events(bag) if start <= t <= stamps[-1]]
    assert [e['event'] for e in events] == ['reset'] + ['none'] * STEPS
    assert (events[0]['seed'], events[0]['split']) == (101, 'train')
    assert [e['episode_step'] for e in events] == list(range(STEPS + 1))

    assert episodes_in_bag(bag) == [{**info, 'return': -0.5}]
    assert messages[EPISODE_TOPIC][0][0] == stamps[-1]


def start_record_command(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, Path, Path]:
    out, err = tmp_path / 'record.out', tmp_path / 'record.err'
    with out.open('w') as stdout, err.open('w') as stderr:
        process = subprocess.Popen([sys.executable, '-m', 'nav_eval.record', *args],
                                   stdout=stdout, stderr=stderr)
    return process, out, err


def stop_process(process: subprocess.Popen, sig: int = signal.SIGINT) -> int:
    if process.poll() is None:
        process.send_signal(sig)
        try:
            process.wait(15)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


def printed_counts(output: str) -> dict[str, int]:
    """Return the per-topic counts the command printed after 'messages written to ...:'."""
    lines = output.split('messages written to', 1)[1].splitlines()[1:]
    pairs = [line.split() for line in lines if line.strip()]
    return {topic: int(n) for n, topic in pairs if topic != 'total'}


def test_record_command_stops_on_sigint_and_leaves_a_readable_bag(tmp_path, namespace):
    bag, steps = tmp_path / 'cmd_bag', 3
    with SimProcess(namespace, params=QUIET_START):
        process, out, err = start_record_command(
            tmp_path, str(bag), '--namespace', namespace, '--ros-args', '-r', '__node:=x')
        try:
            wait_until(lambda: 'publishers matched' in out.read_text(), 30.0,
                       'the record command matching the sim', details=err.read_text)
            with SimClient(namespace, timeout=15.0) as client:
                client.wait_for_sim(30.0)
                wait_until(lambda: client.pub_cmd.get_subscription_count() >= 2, 15.0,
                           'cmd_vel matched by the sim and the record command')
                # drive until the command says every topic reaches it: then the sim has
                # matched its subscriptions too (see warm_up)
                frame, _ = client.reset(seed=7)

                def every_topic_recorded() -> bool:
                    nonlocal frame
                    if 'receiving every nav_sim topic' in out.read_text():
                        return True
                    frame = client.step(0.0, 0.0, frame)
                    return False

                wait_until(every_topic_recorded, 30.0, 'every nav_sim topic at the command',
                           interval=0, details=err.read_text)
                frame, _ = client.reset(seed=103)
                stamps = [frame.stamp_ns]
                for _ in range(steps):
                    frame = client.step(0.0, 1.0, frame)
                    stamps.append(frame.stamp_ns)
        finally:
            code = stop_process(process)
    output, errors = out.read_text(), err.read_text()
    assert code == 0, errors
    assert 'Traceback' not in errors and 'stopped (SIGINT)' in output
    counts = printed_counts(output)
    messages = read_bag(bag)
    assert counts == {topic: len(msgs) for topic, msgs in messages.items()}
    images = since(messages[f'{namespace}/camera/image_raw'], stamps[0])
    assert [t for t, _ in images] == stamps
    assert len(since(messages[f'{namespace}/cmd_vel'], stamps[0])) == steps
    check_metadata(bag, counts)


def test_record_command_duration_without_a_sim(tmp_path, namespace):
    bag = tmp_path / 'empty_bag'
    process, out, err = start_record_command(tmp_path, str(bag), '--namespace', namespace,
                                             '--duration', '0.3')
    try:
        process.wait(30)
    finally:
        stop_process(process, signal.SIGKILL)
    output = out.read_text()
    assert process.returncode == 0, err.read_text()
    assert 'stopped (0.3 s elapsed)' in output
    counts = printed_counts(output)
    assert counts[f'{namespace}/camera/image_raw'] == 0 and sum(counts.values()) == 0
    check_metadata(bag, counts)


def test_an_existing_bag_directory_is_never_overwritten(tmp_path, namespace):
    bag = tmp_path / 'taken'
    bag.mkdir()
    keep = bag / 'keep.txt'
    keep.write_text('precious')
    with pytest.raises(RecordingError, match='exists already'):
        BagRecorder(bag, namespace)
    process, out, err = start_record_command(tmp_path, str(bag))
    try:
        process.wait(30)
    finally:
        stop_process(process, signal.SIGKILL)
    assert process.returncode != 0
    assert 'exists already' in err.read_text() and 'Traceback' not in err.read_text()
    assert list(bag.iterdir()) == [keep] and keep.read_text() == 'precious'


@pytest.mark.parametrize('little_endian', [True, False])
def test_cdr_stamp_is_read_without_deserializing(little_endian):
    store = get_typestore(Stores.ROS2_JAZZY)
    time_type = store.types['builtin_interfaces/msg/Time']
    clock = store.types['rosgraph_msgs/msg/Clock'](clock=time_type(sec=12, nanosec=345))
    data = store.serialize_cdr(clock, 'rosgraph_msgs/msg/Clock', little_endian=little_endian)
    assert cdr_stamp_ns(data) == 12_000_000_345
    assert cdr_stamp_ns(data[:8]) is None


def test_command_line_helpers():
    assert strip_ros_args(['bag', '--ros-args', '-r', '__ns:=/a', '--', '--duration', '2']) \
        == ['bag', '--duration', '2']
    assert strip_ros_args(['--ros-args', '-p', 'x:=1']) == []
    assert format_counts({'/b': 3, '/a': 12}).splitlines() == [
        '   12  /a', '    3  /b', '   15  total']
    latched = bag_qos(qos.LATCHED)
    assert (latched.durability.name, latched.reliability.name, latched.depth) == (
        'TRANSIENT_LOCAL', 'RELIABLE', 1)


def test_unstamped_messages_wait_for_the_first_sim_stamp(tmp_path, namespace):
    bag = tmp_path / 'held_bag'
    context, node = own_node('fake_sim', namespace)
    try:
        profile = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        pub_cmd = node.create_publisher(Twist, 'cmd_vel', profile)
        pub_clock = node.create_publisher(Clock, '/clock', profile)
        with BagRecorder(bag, namespace) as recorder:
            assert recorder.wait_for_publishers(15.0, ('cmd_vel', '/clock'))
            wait_until(lambda: pub_cmd.get_subscription_count() >= 1
                       and pub_clock.get_subscription_count() >= 1, 15.0,
                       'cmd_vel and /clock matched by the recorder')
            for x in (0.1, 0.2):
                pub_cmd.publish(Twist(linear=Vector3(x=x)))
            recorder.annotate({'early': True})
            # the recorder took both commands from the graph (it handles one message at a
            # time, so the first went all the way), yet wrote nothing
            wait_until(lambda: recorder.received == 2, 5.0, 'the early commands at the recorder')
            assert set(recorder.counts.values()) == {0}  # held: no sim time yet
            pub_clock.publish(Clock(clock=Time(sec=5)))
            pub_cmd.publish(Twist(linear=Vector3(x=0.3)))
            wait_until(lambda: recorder.counts[f'{namespace}/cmd_vel'] == 3, 5.0,
                       'the three commands in the bag')
    finally:
        context.try_shutdown()
    messages = read_bag(bag)
    commands = messages[f'{namespace}/cmd_vel']
    assert [(t, m.linear.x) for t, m in commands] == [(5 * 10**9, x) for x in (0.1, 0.2, 0.3)]
    assert [t for t, _ in messages['/clock']] == [5 * 10**9]
    assert [t for t, _ in messages[EPISODE_TOPIC]] == [5 * 10**9]


def test_without_sim_time_annotations_get_wall_clock_time(tmp_path, namespace):
    bag = tmp_path / 'wall_bag'
    before = time.time_ns()
    with BagRecorder(bag, namespace) as recorder:
        recorder.annotate({'seed': np.int64(3), 'values': np.arange(2)})
        assert recorder.counts[EPISODE_TOPIC] == 0  # waits for a sim stamp until close
    after = time.time_ns()
    (stamp, _), = read_bag(bag)[EPISODE_TOPIC]
    assert before <= stamp <= after
    assert episodes_in_bag(bag) == [{'seed': 3, 'values': [0, 1]}]
    with pytest.raises(RecordingError, match='closed'):
        recorder.annotate({})
