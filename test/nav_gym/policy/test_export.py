"""``nav-gym-export``: the policy as ONNX, its parity with PyTorch, and the node without torch.

The policy node runs an export with PyTorch, SB3, Ray and MuJoCo made unimportable.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import onnx
import pytest
from geometry_msgs.msg import TwistStamped

from helpers import interrupt, make_tiny_run
from nav_gym.env.observation import rgb_to_observation
from nav_gym.errors import PolicyModelError
from nav_gym.policy.actors import DQNActor, load_policy
from nav_gym.policy.config import PolicyConfig
from nav_gym.policy.export import export_policy
from nav_gym.policy.exported import META_FILE, ONNX_FILE, OnnxActor, read_export
from nav_gym.training.spec import COMPONENTS, WITHOUT_MEMORY
from nav_sim.core.config import HELDOUT, TRAIN, SimConfig
from nav_sim.core.sim import NavSim
from nav_sim.paths import executable_path
from nav_sim.ros import messages as ros_msgs
from policy_graph import Graph

#: what a robot's install leaves out (requirements/robot.txt): importing any of them fails
HEAVY = ('torch', 'stable_baselines3', 'sb3_contrib', 'mujoco', 'ray')
BLOCKER = f"""import importlib.abc, sys
class _Blocked(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split('.')[0] in {HEAVY!r}:
            raise ImportError(f'{{name}} is not installed on this robot (test)')
sys.meta_path.insert(0, _Blocked())
"""


@pytest.fixture(scope='module')
def run(tmp_path_factory, spaces_only) -> Path:
    return make_tiny_run(tmp_path_factory.mktemp('run'), spaces_only, forward_speed=0.2)


@pytest.fixture(scope='module')
def export(run) -> Path:
    result = subprocess.run([str(executable_path('nav_gym', 'export')), str(run)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.startswith(f'nav-gym-export: wrote {run}/export/policy.onnx'), \
        result.stdout
    return run / 'export'


@pytest.fixture(scope='module')
def bank_observations() -> np.ndarray:
    """200 observations: the first of 100 training and 100 held-out scenarios."""
    sim = NavSim(SimConfig())
    try:
        out = []
        for split in (TRAIN, HELDOUT):
            for seed in range(100):
                sim.reset(seed, split)
                out.append(rgb_to_observation(sim.render()))
        return np.stack(out)
    finally:
        sim.close()


def test_the_export_takes_a_uint8_observation_and_says_what_the_node_needs(run, export):
    graph = onnx.load(str(export / ONNX_FILE)).graph
    (observation,) = graph.input
    assert observation.name == 'observation'
    assert observation.type.tensor_type.elem_type == onnx.TensorProto.UINT8
    # the default learner's input: a 4-frame stack and the previous action's 3 planes
    assert [d.dim_value for d in observation.type.tensor_type.shape.dim] == [1, 15, 84, 84]
    assert [o.name for o in graph.output] == ['q_values']
    meta = json.loads((export / META_FILE).read_text())
    assert meta['actions'] == [[0.03, 0.75], [0.2, 0.0], [0.03, -0.75]]
    assert meta['control_period'] == pytest.approx(0.512)
    assert meta['run'] == str(run.resolve()) and meta['config']['forward_speed'] == 0.2
    assert meta['learner']['n_steps'] == 3 and meta['learner']['double_q'] is True
    _, acting = load_policy(PolicyConfig(model=str(export)))
    assert acting.twists == ((0.03, 0.75), (0.2, 0.0), (0.03, -0.75))


def test_onnx_q_values_equal_pytorchs_on_200_observations_from_both_banks(
        run, export, bank_observations):
    torch_actor = DQNActor(run / 'final_model.zip')
    onnx_actor = OnnxActor(read_export(export))
    import torch
    inputs = []
    for obs in bank_observations:  # each an episode's first frame, as the memory stacks it
        torch_actor.memory.begin_episode()
        inputs.append(torch_actor.memory.observe(obs))
    with torch.no_grad():
        expected = torch_actor.model.q_net(torch.as_tensor(np.stack(inputs))).numpy()
    got = np.stack([onnx_actor.q_values(network_input) for network_input in inputs])
    assert np.abs(got - expected).max() <= 1e-4
    ordered = np.sort(expected, axis=1)
    clear = ordered[:, -1] - ordered[:, -2] > 1e-4  # where the best action is not a tie
    assert clear.sum() >= 150
    assert np.array_equal(got.argmax(1)[clear], expected.argmax(1)[clear])


@pytest.mark.parametrize('flags', [
    {'double_q': False, **COMPONENTS}, {'dueling': True}, {'augment_shift': 4},
    {'augment_colour': 0.2}, {'prioritized_replay': True, **WITHOUT_MEMORY}])
def test_every_learner_flag_exports(tmp_path, spaces_only, flags):
    run = make_tiny_run(tmp_path, spaces_only, steps=16, **flags)
    spec = export_policy(run)
    meta_learner = spec.meta['learner']
    assert all(meta_learner[k] == v for k, v in flags.items())
    torch_actor, onnx_actor = DQNActor(run / 'final_model.zip'), OnnxActor(spec)
    rng = np.random.default_rng(5)
    for _ in range(10):
        obs = rng.integers(0, 256, (3, 84, 84), dtype=np.uint8)
        q_torch, q_onnx = torch_actor.act(obs)[1], onnx_actor.act(obs)[1]
        assert np.allclose(q_torch, q_onnx, atol=1e-4)


@pytest.mark.filterwarnings('ignore:`n_steps=3` is ignored')
@pytest.mark.parametrize('flags', [{'frame_stack': 3, 'previous_action': False},
                                   {'frame_stack': 1, 'previous_action': True},
                                   {'frame_stack': 2, 'previous_action': True}])
def test_a_memory_learner_exports_and_acts_as_its_checkpoint_across_episodes(
        tmp_path, spaces_only, flags):
    run = make_tiny_run(tmp_path, spaces_only, steps=16, **flags)
    spec = export_policy(run)
    channels = 3 * flags.get('frame_stack', 1) + (3 if flags.get('previous_action') else 0)
    assert spec.meta['input']['shape'] == [1, channels, 84, 84]
    torch_actor, onnx_actor = DQNActor(run / 'final_model.zip'), OnnxActor(spec)
    rng = np.random.default_rng(7)
    frames = [rng.integers(0, 256, (3, 84, 84), dtype=np.uint8) for _ in range(4)]
    firsts = []
    for episode in range(3):
        for actor in (torch_actor, onnx_actor):
            actor.begin_episode(episode)
        for t in range(5):
            frame = frames[(episode + t) % len(frames)]
            (a_torch, q_torch), (a_onnx, q_onnx) = torch_actor.act(frame), onnx_actor.act(frame)
            assert np.allclose(q_torch, q_onnx, atol=1e-4), (episode, t)
            if max(q_torch) - sorted(q_torch)[-2] > 1e-3:  # not a tie
                assert a_torch == a_onnx
            if t == 0:
                firsts.append(q_onnx)
            if t == 2:  # an exploring evaluation's random action: the memory's previous one
                for actor in (torch_actor, onnx_actor):
                    actor.carried_out((a_torch + 1) % 3)
    # the memory is used: frame 1 after frame 0 is another input than frame 1 alone (episode
    # 1's first), and a new episode begins afresh
    onnx_actor.begin_episode(None)
    onnx_actor.act(frames[0])
    assert onnx_actor.act(frames[1])[1] != firsts[1]
    onnx_actor.begin_episode(None)
    assert onnx_actor.act(frames[1])[1] == firsts[1]


def test_a_lockstep_evaluation_gives_the_same_outcomes(run, export):
    from nav_eval.evaluation.runner import run_episode
    from nav_gym.env.config import EnvConfig
    from nav_gym.env.navigation import NavigationEnv
    env = NavigationEnv(EnvConfig(sim='embedded', max_episode_steps=30))
    try:
        traces = {}
        for name, actor in (('torch', DQNActor(run / 'final_model.zip')),
                            ('onnx', OnnxActor(read_export(export)))):
            traces[name] = [run_episode(env, actor, seed, split)[1]
                            for seed, split in ((1, TRAIN), (2, TRAIN), (1, HELDOUT))]
    finally:
        env.close()
    for a, b in zip(traces['torch'], traces['onnx'], strict=True):
        assert a['outcome'] == b['outcome']
        assert [s['action'] for s in a['steps']] == [s['action'] for s in b['steps']]
        assert [s['pose'] for s in a['steps']] == [s['pose'] for s in b['steps']]
        assert np.allclose([s['q_values'] for s in a['steps']],
                           [s['q_values'] for s in b['steps']], atol=2e-6)


def _broken(path: Path, export: Path, case: str) -> Path:
    path.mkdir()
    if case != 'no onnx':
        (path / ONNX_FILE).write_bytes((export / ONNX_FILE).read_bytes())
    meta = json.loads((export / META_FILE).read_text())
    if case == 'no json':
        return path
    if case == 'corrupt onnx':
        (path / ONNX_FILE).write_bytes(b'not a network')
    if case == 'bad json':
        (path / META_FILE).write_text('{"format": 1, ')
        return path
    if case == 'missing key':
        del meta['actions']
    if case == 'other observation':
        meta['observation'] = {**meta['observation'], 'shape': [3, 64, 64]}
    (path / META_FILE).write_text(json.dumps(meta))
    return path


BROKEN = {
    'no onnx': 'has no policy.onnx: export the run again',
    'no json': 'has no policy.json: export the run again',
    'bad json': 'cannot read policy.json',
    'missing key': 'policy.json lacks actions',
    'other observation': 'was made for the observation',
    'corrupt onnx': 'cannot read the network',
}


@pytest.mark.parametrize('case', sorted(BROKEN))
def test_a_bad_or_incomplete_export_is_one_line(tmp_path, export, case):
    path = _broken(tmp_path / 'export', export, case)
    with pytest.raises(PolicyModelError, match=BROKEN[case]) as raised:
        load_policy(PolicyConfig(model=str(path)))
    assert len(str(raised.value).splitlines()) == 1


def test_the_node_says_so_in_one_line(tmp_path, export, namespace):
    path = _broken(tmp_path / 'export', export, 'no onnx')
    result = subprocess.run([str(executable_path('nav_gym', 'policy')), '--ros-args', '-r',
                             f'__ns:={namespace}', '-p', f'model:={path}'],
                            capture_output=True, text=True, timeout=120)
    out = result.stdout + result.stderr
    assert result.returncode == 1 and len(out.splitlines()) == 1, out
    assert out.startswith(f'policy_node: export {path} has no policy.onnx'), out


def test_the_node_runs_the_export_without_torch_and_sends_twist_stamped(tmp_path, export,
                                                                         namespace):
    (tmp_path / 'site').mkdir()
    (tmp_path / 'site' / 'sitecustomize.py').write_text(BLOCKER)
    env = {**os.environ, 'PYTHONPATH': str(tmp_path / 'site')}
    probe = subprocess.run([sys.executable, '-c', 'import torch'], env=env,
                           capture_output=True, text=True)
    assert probe.returncode != 0 and 'not installed on this robot' in probe.stderr  # it bites
    process = subprocess.Popen(
        [str(executable_path('nav_gym', 'policy')), '--ros-args', '-r', f'__ns:={namespace}',
         '-p', f'model:={export}', '-p', 'cmd_vel_stamped:=true', '-p',
         'frame_id:=base_footprint', '-p', 'period:=0.4', '-p', 'cmd_vel_rate:=20.0'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    listener = Graph(namespace, cmd_vel_type=TwistStamped)
    try:
        listener.connected(details=lambda: interrupt(process)[1])
        sim = NavSim(SimConfig())
        sim.reset(101, TRAIN)
        image = ros_msgs.image_msg(sim.render(), ros_msgs.stamp_from_ns(4_000_000_000),
                                   'camera_optical_frame')
        sim.close()

        decision = listener.decision(listener.stream(
            image, lambda: next((m for m in reversed(listener.decisions)
                                 if ros_msgs.stamp_to_ns(m.header.stamp) == 4_000_000_000
                                 and listener.decision(m)['action'] >= 0), None),
            20.0, 'a decision on the image'))
        q_values = [decision['q_left'], decision['q_forward'], decision['q_right']]
        assert all(math.isfinite(q) for q in q_values)
        assert decision['action'] == int(np.argmax(q_values))
        count = len(listener.twists)
        listener.spin_until(lambda: len(listener.twists) >= count + 16, 5.0,
                            'repeated commands')
        process.send_signal(signal.SIGINT)
        process.wait(15)
        listener.spin_until(lambda: listener.twists[-1].twist.linear.x == 0.0
                            and listener.twists[-1].twist.angular.z == 0.0, 5.0,
                            'the zero command on exit')
    finally:
        code, text = interrupt(process)
        listener.close()
    assert code == 0 and 'Traceback' not in text, text
    assert f'from {export}/policy.json' in text and 'TwistStamped' in text
    received, last = listener.received[-1], listener.twists[-1]
    assert last.header.frame_id == 'base_footprint'
    assert (last.twist.linear.x, last.twist.angular.z) == (0.0, 0.0)  # the stop on exit
    stamps = [ros_msgs.stamp_to_ns(m.header.stamp) / 1e9 for m in listener.twists]
    # stamped when published, on the node's clock (wall time here), never the image's stamp
    assert all(abs(t - stamps[-1]) < 120.0 for t in stamps) and abs(received - stamps[-1]) < 5.0
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    # 20 Hz repeats between decisions 0.4 s apart: several commands per decision
    assert len(listener.twists) > 3 * len(listener.decisions)
