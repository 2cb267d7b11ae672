"""The trainer's and evaluator's live view, decoded by a headless viewer; the env's budget."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import free_port, wait_until
from nav_gym.env.config import EnvConfig
from nav_gym.env.navigation import STEP_PHASES, NavigationEnv
from nav_sim.viz import topics as live_topics
from nav_sim.viz.client import LiveClient


def test_env_live_view_serves_observation_scene_and_steps():
    port = free_port()
    env = NavigationEnv(EnvConfig(sim='embedded', max_episode_steps=3))
    try:
        assert env.start_live(port) == f'ws://localhost:{port}'
        with LiveClient(port, timeout=15.0) as viewer:
            assert set(viewer.channels) == set(live_topics.ENV_TOPICS)
            topics = [live_topics.OBSERVATION_TOPIC, live_topics.STEP_TOPIC,
                      live_topics.SCENE_TOPIC, live_topics.CAMERA_TOPIC]
            viewer.subscribe(topics)
            wait_until(lambda: all(env.live.view.wanted(t) for t in topics), 15.0,
                       'the subscriptions taking effect')
            obs, info = env.reset(seed=7)
            sent = [(None, obs, 0.0, info)]
            env.note_q_values([0.1, 0.7, 0.2])
            for action in (1, 0, 1):
                obs, reward, terminated, truncated, info = env.step(action)
                sent.append((action, obs, reward, info))
                if terminated or truncated:
                    break
            received: dict[str, list] = {}
            # the step topic goes at most 30 times a second: the first step of the run and
            # the episode's last (truncated at 3) always go, the second may be skipped
            def last_step_arrived() -> bool:
                for message in viewer.receive(0.05):
                    received.setdefault(message.topic, []).append(message.decode())
                steps = received.get(live_topics.STEP_TOPIC, ())
                return bool(steps) and steps[-1].step == len(sent) - 1

            wait_until(last_step_arrived, 15.0, 'the last step on the live view', interval=0,
                       details=lambda: f'received only {sorted(received)}')
    finally:
        env.close()
    steps = received[live_topics.STEP_TOPIC]
    assert steps[0].step == 1 and steps[-1].step == len(sent) - 1
    for msg in steps:
        action, _, reward, info = sent[msg.step]
        assert (msg.action, msg.action_name, msg.event) == (action, info['action_name'],
                                                              info['event'])
        assert (msg.reward, msg.distance) == pytest.approx((reward, info['distance']))
        assert msg.reward_progress == pytest.approx(info['reward_terms']['progress'])
        assert msg.episode_return == pytest.approx(sum(r for _, _, r, _ in sent[:msg.step + 1]))
    assert list(steps[0].q_values) == pytest.approx([0.1, 0.7, 0.2])
    assert len(steps[-1].q_values) == 0  # Q-values belong to the step they were noted for
    # the first message of a topic always goes: the reset's observation, channel-last
    first = received[live_topics.OBSERVATION_TOPIC][0]
    assert (first.width, first.height, first.encoding) == (84, 84, 'rgb8')
    assert np.array_equal(first.data.reshape(84, 84, 3), sent[0][1].transpose(1, 2, 0))
    scene = received[live_topics.SCENE_TOPIC][0].markers
    goal = next(m for m in scene if m.ns == 'goal' and m.id == 0)
    assert (goal.pose.position.x, goal.pose.position.y) == pytest.approx(
        sent[0][3]['goal'], abs=1e-3)


def test_env_step_budget_adds_up_and_goes_to_diagnostics():
    from diagnostic_msgs.msg import DiagnosticArray
    env = NavigationEnv(EnvConfig(sim='embedded', max_episode_steps=200))
    reports: list[dict[str, float]] = []
    try:
        name = f'{env.client.node.get_fully_qualified_name()}: env step'

        def on_diagnostics(msg: DiagnosticArray) -> None:
            reports.extend({kv.key: float(kv.value) for kv in s.values}
                           for s in msg.status if s.name == name)

        env.client.node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        env.reset(seed=3)

        def stepped_until_a_report() -> bool:  # published about once a second while stepping
            for _ in range(20):
                _, _, terminated, truncated, _ = env.step(0)
                if terminated or truncated:
                    env.reset(seed=4)
            return env.client.spin_until(lambda: bool(reports), 0.02)

        wait_until(stepped_until_a_report, 30.0, 'an env step report on /diagnostics',
                   interval=0)
        budget = env.time_budget()['env_step']
    finally:
        env.close()
    report = reports[0]
    assert {f'{p}_ms' for p in STEP_PHASES} | {'step_ms', 'steps_per_s', 'steps'} <= set(report)
    assert report['transport_ms'] > 0 and report['steps'] > 0
    assert budget['steps'] >= 30  # resets are not steps; the first step sets the reference
    assert budget['transport_ms'] > 0 and budget['image_ms'] > 0
    assert budget['live_ms'] == 0.0  # no observer
    parts = sum(budget[f'{p}_ms'] for p in STEP_PHASES)
    assert parts <= budget['step_ms'] * 1.01
    assert parts >= 0.5 * budget['step_ms']  # the env's own work is most of a bare loop
