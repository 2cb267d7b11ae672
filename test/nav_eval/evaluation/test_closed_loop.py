"""Closed-loop evaluation: the policy node driving a realtime sim, and what is read from it.

The reconstruction (which command acted in which period, how late) on constructed timestamps,
then a tiny model end to end at a high realtime rate through ``nav-eval-evaluate --closed-loop``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO, make_tiny_run, wait_until
from nav_eval.analysis.closed_loop import (
    Decision,
    Tick,
    commands_in_effect,
    image_latencies,
    latency_summary,
)
from nav_eval.reporting.closed_loop import section_closed_loop

MS = 1_000_000
P = 512 * MS  # a control period of sim time


def tick(k: int, published_ms: float, twist=(0.12, 0.0), event='none') -> Tick:
    """Return period ``k`` (stamped k periods), published at ``published_ms`` wall ms."""
    return Tick(k * P, round(published_ms * MS), {
        'event': event, 'done': event != 'none', 'linear': twist[0], 'angular': twist[1]})


def decision(image_k: int, published_ms: float, action: int = 1) -> Decision:
    twist = {0: (0.03, 0.75), 1: (0.12, 0.0), 2: (0.03, -0.75), -1: (0.0, 0.0)}[action]
    return Decision(image_k * P, round(published_ms * MS), {
        'action': action, 'linear': twist[0], 'angular': twist[1], 'q_left': 0.1,
        'q_forward': 0.2, 'q_right': 0.3, 'inference_ms': 2.0})


def test_the_command_in_effect_is_the_newest_decision_before_the_tick():
    decisions = [decision(0, 100.0, 0), decision(1, 612.0, 1)]
    ticks = [tick(1, 500.0, (0.03, 0.75)), tick(2, 1000.0, (0.12, 0.0))]
    commands, races, mismatches = commands_in_effect(ticks, decisions, since_ns=0,
                                                     timeout_ns=2 * P)
    assert commands == decisions and (races, mismatches) == (0, 0)


def test_a_reset_and_the_timeout_leave_no_command():
    decisions = [decision(0, 100.0)]
    stopped = (0.0, 0.0)
    commands, _, mismatches = commands_in_effect([tick(1, 500.0, stopped)], decisions,
                                                 since_ns=200 * MS, timeout_ns=2 * P)
    assert commands == [None] and mismatches == 0   # published before the reset
    commands, _, _ = commands_in_effect([tick(3, 1200.0, stopped)], decisions, since_ns=0,
                                        timeout_ns=1000 * MS)
    assert commands == [None]                       # older than cmd_vel_timeout


def test_a_decision_that_reached_the_sim_after_its_tick_is_a_corrected_race():
    # published 1 ms before the tick, but the twist the sim drove is the decision before it
    decisions = [decision(0, 100.0, 0), decision(1, 499.0, 1)]
    commands, races, mismatches = commands_in_effect([tick(1, 500.0, (0.03, 0.75))],
                                                     decisions, 0, 2 * P)
    assert commands == [decisions[0]] and (races, mismatches) == (1, 0)
    # a twist no candidate explains is a mismatch (the newest is kept)
    commands, races, mismatches = commands_in_effect([tick(1, 500.0, (0.5, 0.5))],
                                                     decisions, 0, 2 * P)
    assert commands == [decisions[1]] and (races, mismatches) == (0, 1)
    # a terminal period stops the motors: its twist says nothing
    assert commands_in_effect([tick(1, 500.0, (0.0, 0.0), 'goal')], decisions, 0,
                              2 * P)[1:] == (0, 0)


def test_latency_is_how_late_the_answer_to_an_image_acted_in_sim_and_wall_time():
    first = tick(0, 0.0)
    ticks = [tick(1, 512.0), tick(2, 1024.0), tick(3, 1536.0)]
    d0, d1 = decision(0, 300.0), decision(1, 1100.0)   # d1 misses tick 2: one period late
    commands = [d0, d0, d1]
    images = {0: 5 * MS, P: 517 * MS, 2 * P: 1029 * MS}
    out = image_latencies(first, ticks, commands, [d0, d1], images)
    assert out.sim == [0.0, 0.512]
    assert out.wall == pytest.approx([0.295, 0.583])
    assert out.inference == [0.002, 0.002] and out.skipped == 1   # image 2: nobody answered
    summary = latency_summary(out.sim, out.wall, 0.512, out.inference)
    assert summary['periods'] == {'0': 0.5, '1': 0.5}
    assert summary['wall_ms']['max'] == pytest.approx(583.0)


def test_a_stop_answers_no_image_even_with_the_stale_image_stamp():
    # at 4x real time on a loaded machine image 1 went stale: the node stopped, carrying the
    # stale image's stamp (a KeyError here once ended a closed-loop evaluation)
    first = tick(0, 0.0)
    ticks = [tick(1, 128.0), tick(2, 256.0, (0.0, 0.0))]
    d0, stop = decision(0, 60.0), decision(1, 250.0, -1)
    images = {0: 2 * MS, P: 130 * MS}
    out = image_latencies(first, ticks, [d0, stop], [d0, stop], images)
    assert out.sim == [0.0] and out.skipped == 1


@pytest.fixture(scope='module')
def evaluated(tmp_path_factory, spaces_only) -> Path:
    """Evaluate a tiny run in lockstep and closed loop at 8x real time on two seeds.

    Its learner has memory (a 2-frame stack and the previous action), which both loops keep
    through the one actor.
    """
    run = make_tiny_run(tmp_path_factory.mktemp('run'), spaces_only, max_episode_steps=15,
                        frame_stack=2)
    result = subprocess.run(
        [str(Path(sys.prefix) / 'bin' / 'nav-eval-evaluate'), str(run), '--closed-loop',
         '--realtime-rate', '8', '--heldout-seeds', '201-202'],
        capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'Traceback' not in result.stderr
    return run


def test_closed_loop_writes_what_lockstep_writes_on_the_same_seeds(evaluated):
    out = evaluated / 'eval_closed_loop'
    results = json.loads((out / 'results.json').read_text())
    names = [s['name'] for s in results['sets']]
    assert names == ['dqn_heldout', 'rt8_heldout']
    lockstep, loop = results['sets']
    assert lockstep['seeds'] == loop['seeds'] == [201, 202]
    assert loop['realtime_rate'] == 8.0 and loop['decision_period_s'] == pytest.approx(0.064)
    assert (out / 'results.md').read_text().count('\n') >= 4
    assert (out / 'episodes.csv').read_text().count('rt8_heldout') == 2
    for episode in loop['episodes']:
        trace = json.loads((out / 'traces' / 'rt8_heldout'
                            / f"seed_{episode['seed']}.json").read_text())
        assert len(trace['steps']) == episode['length'] <= 15
        assert sum(s['reward'] for s in trace['steps']) == pytest.approx(episode['return'],
                                                                        abs=1e-4)
        acted = [s for s in trace['steps'] if s['action'] >= 0]
        assert acted and all(s['action'] == int(np.argmax(s['q_values'])) for s in acted)
        frames = np.load(out / 'traces' / 'rt8_heldout' / f"seed_{episode['seed']}_frames.npz")
        assert frames['obs'].shape == (episode['length'] + 1, 3, 84, 84)
    latency = loop['latency']
    assert latency['images_acted_on'] > 0 and latency['wall_ms']['median'] > 0.0
    assert sum(latency['periods'].values()) == pytest.approx(1.0, abs=1e-3)
    assert loop['checks']['twist_mismatches'] == 0


def test_the_closed_loop_bag_holds_the_decisions_and_replays_the_layout(evaluated):
    from nav_eval.recording.bags import episodes_in_bag, read_bag
    from nav_sim.viz import topics as live_topics
    from nav_sim.viz.layout import LIVE_ONLY_TOPICS, referenced_topics
    bag = evaluated / 'eval_closed_loop' / 'bags' / 'rt8_heldout'
    messages = read_bag(bag)
    layout = json.loads((REPO / 'config' / 'foxglove'
                         / 'visnav.json').read_text())
    wanted = referenced_topics(layout) - set(LIVE_ONLY_TOPICS)
    assert wanted <= set(messages), sorted(wanted - set(messages))
    decisions = [m for _, m in messages[live_topics.DECISION_TOPIC]]
    assert decisions and list(decisions[0].name)[:3] == ['action', 'linear', 'angular']
    assert [e['seed'] for e in episodes_in_bag(bag)] == [201, 202]


def test_memory_acts_in_the_closed_loop_as_in_lockstep_on_the_images_it_decided_on(evaluated):
    """The policy node's decisions, replayed through the lockstep evaluation's actor.

    Given the same images in the same order (the timing the closed loop happened to have),
    the actor's history, begun at each episode's start, gives the node's very Q-values.  The
    node's history begins again at the sim's reset event and after a stale-image stop (action
    -1); a decision it made on an image before it took the reset event, it made again after.
    """
    from nav_eval.recording.bags import read_bag
    from nav_gym.policy.actors import DQNActor
    from nav_sim.viz import topics as live_topics
    out = evaluated / 'eval_closed_loop'
    bag = read_bag(out / 'bags' / 'rt8_heldout', [live_topics.DECISION_TOPIC])
    decisions = []
    for _, msg in bag[live_topics.DECISION_TOPIC]:
        values = dict(zip(msg.name, msg.position, strict=True))
        decisions.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec,
                          int(values['action']), values['inference_ms'] > 0.0,
                          (values['q_left'], values['q_forward'], values['q_right'])))
    actor = DQNActor(evaluated / 'final_model.zip')
    compared = 0
    for seed in (201, 202):
        trace = json.loads((out / 'traces' / 'rt8_heldout' / f'seed_{seed}.json').read_text())
        frames = np.load(out / 'traces' / 'rt8_heldout' / f'seed_{seed}_frames.npz')['obs']
        steps = trace['steps']
        period = (steps[1]['stamp_ns'] - steps[0]['stamp_ns']) // (steps[1]['step']
                                                                   - steps[0]['step'])
        stamps = [steps[0]['stamp_ns'] - steps[0]['step'] * period] + [
            s['stamp_ns'] for s in steps]
        frame_of = {stamp: i for i, stamp in enumerate(stamps)}
        mine = [d for d in decisions if d[0] in frame_of]  # decisions on this episode's images
        # the node's actor calls: fresh decisions; one made again on the same image replaces
        # the one before it (made before the reset event), and a stop begins the history again
        calls: list[tuple[int, tuple[float, ...]] | None] = []
        for stamp, action, fresh, q_values in mine:
            if action < 0:
                calls.append(None)
            elif fresh:
                if calls and calls[-1] is not None and calls[-1][0] == stamp:
                    calls.pop()
                calls.append((stamp, q_values))
        assert sum(call is not None for call in calls) >= 3, (seed, mine)
        actor.begin_episode(seed)
        for call in calls:
            if call is None:
                actor.begin_episode(None)
                continue
            stamp, q_values = call
            _, replayed = actor.act(frames[frame_of[stamp]])
            assert replayed == pytest.approx(q_values, abs=1e-6), (seed, stamp)
            compared += 1
    assert compared >= 6


def test_the_report_puts_lockstep_and_real_time_side_by_side(evaluated):
    results = json.loads((evaluated / 'eval_closed_loop' / 'results.json').read_text())
    text = '\n'.join(section_closed_loop(results, 'runs/tiny'))
    assert '| DQN final, held-out seeds | lockstep | 2 |' in text
    assert '| rt8_heldout | 0.064 |' in text and '**8x real time**' in text
    assert 'Not evaluated yet' in '\n'.join(section_closed_loop(None, 'runs/tiny'))


def test_no_process_is_left_behind(evaluated):
    ps = subprocess.run(['ps', '-eo', 'args'], capture_output=True, text=True).stdout
    left = [line for line in ps.splitlines() if str(evaluated) in line  # the policy node
            or ('visnav_closed_loop_' in line and 'realtime_rate:=8.0' in line)]  # the sim
    assert not left, left


def test_a_killed_sim_is_named_as_dead(tmp_path, spaces_only):
    (tmp_path / 'run').mkdir()
    run = make_tiny_run(tmp_path / 'run', spaces_only, max_episode_steps=40)
    process = subprocess.Popen(
        [str(Path(sys.prefix) / 'bin' / 'nav-eval-evaluate'), str(run), '--closed-loop',
         '--realtime-rate', '1', '--heldout-seeds', '201-203', '--no-record'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        marker = f'visnav_closed_loop_{process.pid}_1'

        def sim_pid() -> int | None:
            ps = subprocess.run(['pgrep', '-f', f'nav_sim.sim_node.*{marker}'],
                                capture_output=True, text=True).stdout.split()
            return int(ps[0]) if ps else None
        pid = wait_until(sim_pid, 300.0, 'the closed loop sim')
        time.sleep(3.0)  # into the episodes
        os.kill(pid, signal.SIGKILL)
        out, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 1, out + err
    (line,) = err.strip().splitlines()
    assert f'sim_node (pid {pid}) was killed by signal SIGKILL (9)' in line, line
