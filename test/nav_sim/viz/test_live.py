"""The live view: a headless Foxglove client of a live sim node, and the shipped layout."""

from __future__ import annotations

import json
import math
import socket

import numpy as np
import pytest

from helpers import REPO, free_port, wait_until
from nav_sim import interface
from nav_sim.core.config import SimConfig
from nav_sim.core.world import World
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import SimProcess
from nav_sim.ros.settings import NodeConfig
from nav_sim.viz import topics as live_topics
from nav_sim.viz.client import LiveClient
from nav_sim.viz.server import EpisodeScene, LiveView

LAYOUT = REPO / 'config' / 'foxglove' / 'visnav.json'
QUIET = {'publish_clock': False}


def test_shipped_layout_is_the_generated_one_and_names_known_topics():
    from nav_sim.viz.layout import LIVE_ONLY_TOPICS, layout_json, referenced_topics
    shipped = json.loads(LAYOUT.read_text())
    assert shipped == json.loads(layout_json())
    topics = referenced_topics(shipped)
    assert {live_topics.CAMERA_TOPIC, live_topics.OBSERVATION_TOPIC, live_topics.SCENE_TOPIC,
            live_topics.ROBOT_TOPIC, live_topics.STEP_TOPIC, live_topics.TRAINING_TOPIC,
            live_topics.DIAGNOSTICS_TOPIC} <= topics
    assert topics <= set(live_topics.TOPIC_TYPES)
    # a trainer/evaluator serves all of them; the closed-loop evaluation also the policy's
    assert topics <= set(live_topics.CLOSED_LOOP_TOPICS)
    # the live-only topics are on the training tab; the episode tab replays from a bag; the
    # policy node's on their own tab (only a graph with the policy node has them)
    episode_tab, training_tab, policy_tab = shipped['content']['tabs']
    assert not referenced_topics(episode_tab) & set(LIVE_ONLY_TOPICS + live_topics.POLICY_TOPICS)
    assert set(LIVE_ONLY_TOPICS) <= referenced_topics(training_tab)
    assert referenced_topics(policy_tab) == set(live_topics.POLICY_TOPICS)


def test_scene_of_an_episode_round_trips_through_cdr():
    config = SimConfig()
    world = World(config)
    try:
        arena = live_topics.ArenaScene.from_world(world)
    finally:
        world.close()
    assert len(arena.walls) == 4 and len(arena.slots) == len(world.obstacle_geoms)
    scenario = {'goal': [0.4, -0.3], 'obstacles': [{'slot': 2, 'x': 0.1, 'y': 0.2, 'yaw': 0.5}]}
    scene = EpisodeScene(arena)
    scene.reset(scenario, (0.0, 0.0, math.pi / 2))
    scene.step((0.0, 0.06, math.pi / 2))
    markers = live_topics.from_cdr(live_topics.to_cdr(scene.scene(5), live_topics.MARKERS_TYPE),
                                   live_topics.MARKERS_TYPE).markers
    goal = next(m for m in markers if m.ns == 'goal' and m.id == 0)
    assert (goal.pose.position.x, goal.pose.position.y) == (0.4, -0.3)
    obstacle = next(m for m in markers if m.ns == 'obstacles')
    assert obstacle.type == 3 and obstacle.scale.z == pytest.approx(2 * arena.slots[2].half_z)
    robot = live_topics.from_cdr(live_topics.to_cdr(scene.robot(5), live_topics.MARKERS_TYPE),
                                 live_topics.MARKERS_TYPE).markers
    path = next(m for m in robot if m.ns == 'path')
    assert [(p.x, p.y) for p in path.points] == [(0.0, 0.0), (0.0, 0.06)]
    body = next(m for m in robot if m.ns == 'robot' and m.id == 0)
    assert body.pose.position.y == pytest.approx(0.06)
    frustum = next(m for m in robot if m.ns == 'robot' and m.id == 2)
    # the camera looks along +y (yaw 90 deg): every frustum corner is ahead of the robot
    assert all(p.y >= 0.06 - 1e-9 for p in frustum.points)


def test_the_scene_is_drawn_in_the_sims_odom_frame():
    default = live_topics.arena_for()
    assert default.frame == interface.ODOM_FRAME == NodeConfig().odom_frame
    arena = live_topics.arena_for({'odom_frame': 'robot1/odom'})
    scene = EpisodeScene(arena)
    scene.reset({'goal': [0.4, -0.3], 'obstacles': []}, (0.0, 0.0, 0.0))
    for msg in (scene.scene(5), scene.robot(5)):
        frames = {m.header.frame_id for m in msg.markers}
        assert frames == {'robot1/odom'}


def test_live_view_with_nobody_connected_builds_nothing():
    live = LiveView(free_port(), live_topics.SIM_TOPICS)
    try:
        built = []
        assert not live.log(live_topics.CAMERA_TOPIC, lambda: built.append(1), 0)
        assert built == [] and not live.wanted(live_topics.SCENE_TOPIC)
    finally:
        live.close()


def test_headless_client_watches_a_live_sim_node(namespace):
    port = free_port()
    with SimProcess(namespace, params={**QUIET, 'live_port': port}) as sim, \
            SimClient(namespace, timeout=15.0) as client:
        client.wait_for_sim(30.0, sim.failure)
        with LiveClient(port, timeout=15.0) as viewer:
            for topic in live_topics.SIM_TOPICS:
                channel = viewer.channels[topic]
                assert channel['encoding'] == 'cdr'
                assert channel['schemaEncoding'] == 'ros2msg'
                assert channel['schemaName'] == live_topics.TOPIC_TYPES[topic]
            viewer.subscribe([live_topics.CAMERA_TOPIC, live_topics.SCENE_TOPIC,
                              live_topics.ROBOT_TOPIC, live_topics.EVENT_TOPIC])
            frame, scenario = client.reset(seed=3, split='train')
            received: dict[str, list] = {}
            frames = {frame.stamp_ns: frame}

            def ours(topic: str) -> list:  # messages of the periods this client drove
                return [m for m in received.get(topic, ()) if m.log_time_ns in frames]

            def every_topic_came() -> bool:
                return (len(ours(live_topics.CAMERA_TOPIC)) >= 3
                        and all(ours(topic) for topic in (live_topics.SCENE_TOPIC,
                                                          live_topics.ROBOT_TOPIC,
                                                          live_topics.EVENT_TOPIC)))

            def step_and_receive() -> bool:
                nonlocal frame
                frame = client.step(0.0, 0.5, frame)
                frames[frame.stamp_ns] = frame
                for message in viewer.receive(0.02):
                    received.setdefault(message.topic, []).append(message)
                return every_topic_came()

            # subscriptions take effect asynchronously, and images and the robot go at most
            # 15 times a second: step until every topic came for the episode we drive
            wait_until(step_and_receive, 30.0, 'every subscribed topic for our periods',
                       interval=0, details=lambda: f'only {sorted(received)} arrived')
    for message in ours(live_topics.CAMERA_TOPIC):
        msg = message.decode()
        assert (msg.width, msg.height, msg.encoding) == (128, 96, 'rgb8')
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        assert stamp == message.log_time_ns
        sent = frames[stamp].image  # the very image the ROS client got for that period
        assert np.array_equal(msg.data, np.frombuffer(bytes(sent.data), np.uint8))
    scene = ours(live_topics.SCENE_TOPIC)[-1].decode().markers
    goal = next(m for m in scene if m.ns == 'goal' and m.id == 0)
    assert goal.pose.position.x == pytest.approx(scenario['goal'][0], abs=1e-3)
    assert goal.pose.position.y == pytest.approx(scenario['goal'][1], abs=1e-3)
    assert sum(m.ns == 'obstacles' for m in scene) == len(scenario['obstacles'])
    last_robot = ours(live_topics.ROBOT_TOPIC)[-1]
    body = next(m for m in last_robot.decode().markers if m.ns == 'robot' and m.id == 0)
    x, y, _ = frames[last_robot.log_time_ns].pose
    assert (body.pose.position.x, body.pose.position.y) == pytest.approx((x, y), abs=1e-9)
    events = [m.decode().status[0] for m in received[live_topics.EVENT_TOPIC]]
    assert all(s.name == 'nav_sim/episode' for s in events)


def test_bad_live_ports_are_clear_errors():
    from nav_sim.errors import ConfigError
    from nav_sim.ros.settings import NodeConfig
    from nav_sim.viz.server import LiveViewError
    with pytest.raises(ConfigError, match=r'live_port must be in \[0, 65535\], got 70000'):
        NodeConfig(live_port=70000)
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        with pytest.raises(LiveViewError, match='choose another port'):
            LiveView(taken.getsockname()[1], live_topics.SIM_TOPICS)
