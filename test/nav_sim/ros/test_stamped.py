"""``cmd_vel`` as TwistStamped (``cmd_vel_stamped``): the sim, its clients and the recorder.

The sim obeys it in lockstep and in real time, a client of the other setting is named in one
line, and a bag records either type.
"""

from __future__ import annotations

import pytest
from geometry_msgs.msg import Twist, TwistStamped

from helpers import interrupt, wait_until
from nav_eval.recording.bags import TYPESTORE
from nav_eval.recording.recorder import BagRecorder
from nav_sim import interface
from nav_sim.errors import SimConflictError
from nav_sim.paths import executable_path
from nav_sim.ros import messages as ros_msgs
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import ros_args


def start_node(namespace: str, **params: object):
    import subprocess
    return subprocess.Popen([str(executable_path('nav_sim', 'sim_node')),
                             *ros_args(namespace, params)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_the_default_stays_twist():
    assert interface.cmd_vel_type(False) == interface.CMD_VEL_TYPE == 'geometry_msgs/msg/Twist'
    assert ros_msgs.cmd_vel_class(False) is Twist
    msg = ros_msgs.cmd_vel_msg(0.1, -0.5)
    assert isinstance(msg, Twist) and (msg.linear.x, msg.angular.z) == (0.1, -0.5)
    stamped = ros_msgs.cmd_vel_msg(0.1, -0.5, ros_msgs.stamp_from_ns(7), 'base_link')
    assert isinstance(stamped, TwistStamped) and stamped.header.frame_id == 'base_link'
    assert ros_msgs.twist_of(stamped) is stamped.twist and ros_msgs.twist_of(msg) is msg


def test_lockstep_steps_on_twist_stamped_and_a_twist_client_is_named(namespace, tmp_path):
    process = start_node(namespace, cmd_vel_stamped=True)
    try:
        with SimClient(namespace, timeout=15.0, cmd_vel_stamped=True) as client:
            client.wait_for_sim(30.0)
            bag = tmp_path / 'bag'
            with BagRecorder(bag, namespace, cmd_vel_stamped=True) as recorder:
                assert recorder.wait_for_publishers(15.0, (interface.IMAGE_TOPIC,))
                wait_until(lambda: client.pub_cmd.get_subscription_count() >= 2, 15.0,
                           'the recorder on cmd_vel')
                frame, _ = client.reset(seed=104)
                for _ in range(3):
                    frame = client.step(0.0, 0.75, frame)
                assert frame.twist[1] == pytest.approx(0.75)  # it turned as commanded
                # the client's cmd_vel keeps one message: a burst may reach the bag in part
                wait_until(lambda: recorder.counts.get(f'{namespace}/cmd_vel', 0) >= 1, 10.0,
                           'a command in the bag', details=lambda: recorder.counts)
            # a client of the workshop's Twist: named in one line, not a time-out
            with SimClient(namespace, timeout=15.0) as twist_client, \
                    pytest.raises(SimConflictError) as refused:
                twist_client.wait_for_sim(15.0)
        message = str(refused.value)
        assert len(message.splitlines()) == 1
        assert f'{namespace}/sim_node takes {namespace}/cmd_vel as geometry_msgs/msg/TwistStamped'\
            in message and 'cmd_vel_stamped' in message, message
    finally:
        code, output = interrupt(process)
    assert code == 0 and 'Traceback' not in output, output
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types[f'{namespace}/cmd_vel'] == interface.CMD_VEL_STAMPED_TYPE
        commands = [TYPESTORE.deserialize_cdr(raw, c.msgtype) for c, _, raw in
                    reader.messages([c for c in reader.connections
                                     if c.topic == f'{namespace}/cmd_vel'])]
    assert commands and all(m.twist.angular.z == 0.75 for m in commands)


def test_a_stamped_client_of_a_twist_sim_is_named(namespace):
    process = start_node(namespace)
    try:
        with SimClient(namespace, timeout=15.0, cmd_vel_stamped=True) as client, \
                pytest.raises(SimConflictError, match='as geometry_msgs/msg/Twist, but .* uses '
                              'geometry_msgs/msg/TwistStamped'):
            client.wait_for_sim(15.0)
    finally:
        code, output = interrupt(process)
    assert code == 0, output


def test_realtime_follows_twist_stamped(namespace):
    process = start_node(namespace, mode='realtime', realtime_rate=4.0, cmd_vel_stamped=True)
    try:
        with SimClient(namespace, timeout=15.0, cmd_vel_stamped=True) as client:
            client.wait_for_sim(30.0)
            client.reset(seed=104)
            command = ros_msgs.cmd_vel_msg(0.0, 1.0, client.node.get_clock().now().to_msg())

            def turning() -> bool:
                client.pub_cmd.publish(command)
                return client.spin_until(
                    lambda: client._latest.twist[1] == pytest.approx(1.0), 0.05)

            wait_until(turning, 10.0, 'the realtime sim turning on a TwistStamped', interval=0)
    finally:
        code, output = interrupt(process)
    assert code == 0 and 'Traceback' not in output, output


def test_the_setting_is_fixed_once_the_sim_runs(namespace):
    process = start_node(namespace)
    try:
        with SimClient(namespace, timeout=15.0) as client:
            client.wait_for_sim(30.0)
            from nav_sim.errors import ScenarioError
            with pytest.raises(ScenarioError, match='cmd_vel_stamped'):
                client.set_parameters(cmd_vel_stamped=True)
    finally:
        code, output = interrupt(process)
    assert code == 0, output
