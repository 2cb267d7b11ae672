"""Contract tests of visnav/Navigation-v0 through the real ROS graph."""

from __future__ import annotations

import re
import signal
import time

import gymnasium as gym
import numpy as np
import pytest
from std_srvs.srv import Trigger

import nav_gym
from helpers import wait_until
from nav_gym.env.checks import check_checkers, drive_forward, drive_to_goal
from nav_gym.env.config import EnvConfig
from nav_gym.env.navigation import NavigationEnv
from nav_gym.env.reward import reward_terms
from nav_gym.errors import InvalidActionError, ResetNeededError
from nav_sim.errors import ScenarioError, SimConflictError, SimUnavailableError
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import SimProcess
from nav_sim.ros.sim_graph import CONFLICT


def test_registered_with_gymnasium():
    assert nav_gym.ENV_ID == 'visnav/Navigation-v0'
    assert nav_gym.ENV_ID in gym.registry
    # what gym.make (and rl-baselines3-zoo's --gym-packages nav_gym) loads is the env class
    from gymnasium.envs.registration import load_env_creator
    assert load_env_creator(gym.spec(nav_gym.ENV_ID).entry_point) is NavigationEnv


def test_spaces_and_observations(env):
    assert env.observation_space == gym.spaces.Box(0, 255, (3, 84, 84), np.uint8)
    assert env.action_space == gym.spaces.Discrete(3)
    obs, info = env.reset(seed=101)
    assert obs.shape == (3, 84, 84) and obs.dtype == np.uint8
    assert env.observation_space.contains(obs)
    assert set(info) >= {'scenario', 'distance', 'pose', 'goal', 'seed', 'split', 'depth'}
    depths = [info['depth']]
    for action in (0, 1, 2):
        obs, reward, terminated, truncated, info = env.step(action)
        assert env.observation_space.contains(obs)
        assert isinstance(reward, float) and isinstance(terminated, bool)
        depths.append(info['depth'])
    # the camera's coarse depth, a training target beside the observation (nav_sim.core.depth)
    from nav_sim.core.depth import DEPTH_RANGE, DEPTH_SHAPE
    for depth in depths:
        assert depth.shape == DEPTH_SHAPE and depth.dtype == np.float32
        assert (depth > 0).all() and (depth <= DEPTH_RANGE).all()
    assert not np.array_equal(depths[0], depths[1])  # a turn changes what the camera sees


def test_both_checkers_pass_without_warnings(env):
    checks = check_checkers(env)
    assert [c.measured for c in checks] == ['no errors, no warnings'] * 2


def test_same_seed_same_scenario_and_first_observation(env):
    a, info_a = env.reset(seed=203, options={'split': 'heldout'})
    env.step(1)
    b, info_b = env.reset(seed=203, options={'split': 'heldout'})
    assert info_a['scenario']['goal'] == info_b['scenario']['goal']
    assert info_a['scenario']['layout'] == info_b['scenario']['layout']
    assert np.array_equal(a, b)
    c, info_c = env.reset(seed=204, options={'split': 'heldout'})
    assert info_c['scenario']['goal'] != info_a['scenario']['goal']


def test_unseeded_resets_follow_the_env_generator(env):
    env.reset(seed=9)
    seeds_a = [env.reset()[1]['seed'] for _ in range(3)]
    env.reset(seed=9)
    seeds_b = [env.reset()[1]['seed'] for _ in range(3)]
    assert seeds_a == seeds_b and len(set(seeds_a)) == 3


def test_reward_formula_on_constructed_situations():
    cfg = EnvConfig()
    t = reward_terms(1.00, 0.90, 'none', cfg)
    assert t == pytest.approx({'progress': 0.2, 'step': -0.01, 'goal': 0.0, 'collision': 0.0})
    t = reward_terms(0.15, 0.09, 'goal', cfg)
    assert sum(t.values()) == pytest.approx(2.0 * 0.06 - 0.01 + 5.0)
    t = reward_terms(0.50, 0.52, 'collision', cfg)
    assert sum(t.values()) == pytest.approx(2.0 * -0.02 - 0.01 - 1.0)


def test_step_reward_matches_its_terms_and_the_distance(env):
    _, info = env.reset(seed=105)
    previous = info['distance']
    for action in (1, 1, 0, 1):
        _, reward, terminated, _, info = env.step(action)
        terms = info['reward_terms']
        assert reward == pytest.approx(sum(terms.values()))
        assert terms['progress'] == pytest.approx(2.0 * (previous - info['distance']))
        previous = info['distance']
        if terminated:
            break


def test_goal_terminates_with_bonus_and_stops_motors(env):
    seed, trace = drive_to_goal(env, range(101, 131))
    assert seed is not None, 'no seed reached the goal with the privileged driver'
    last = trace[-1]
    assert last['terminated'] and not last['truncated'] and last['is_success']
    assert last['reward_terms']['goal'] == 5.0
    assert last['wheels'] == [0.0, 0.0]  # stopped by the sim within the period
    assert trace[-2]['wheels'] != [0.0, 0.0]  # (it was driving before)
    assert last['wheels_after_stop'] == [0.0, 0.0]
    assert not any(t['terminated'] or t['truncated'] for t in trace[:-1])


def test_collision_terminates_with_penalty_and_stops_motors(env):
    trace = drive_forward(env, 103)
    last = trace[-1]
    assert last['event'] == 'collision' and last['terminated'] and not last['truncated']
    assert last['reward_terms']['collision'] == -1.0
    assert last['wheels'] == [0.0, 0.0] and trace[-2]['wheels'] != [0.0, 0.0]
    assert last['wheels_after_stop'] == [0.0, 0.0]


def test_time_limit_truncates_only(env):
    short = NavigationEnv(namespace=env.namespace, sim='attach', max_episode_steps=4)
    try:
        short.reset(seed=106)
        flags = [short.step(0)[2:4] for _ in range(4)]
        assert flags == [(False, False)] * 3 + [(False, True)]
        with pytest.raises(ResetNeededError):
            short.step(0)
    finally:
        short.close()


@pytest.mark.parametrize('action', [3, -1, 1.0, '1', None, True, np.array([0, 1])])
def test_invalid_actions_are_rejected(env, action):
    env.reset(seed=107)
    with pytest.raises(InvalidActionError, match='action'):
        env.step(action)


@pytest.mark.parametrize('action', [np.int64(1), np.array(2), np.array([0])])
def test_numpy_actions_are_accepted(env, action):
    env.reset(seed=107)
    info = env.step(action)[4]
    assert info['action_name'] == ('left', 'forward', 'right')[int(np.asarray(action).item())]
    assert info['step'] == 1


def test_unknown_split_is_a_clear_error(env):
    with pytest.raises(ScenarioError, match='unknown split'):
        env.reset(seed=1, options={'split': 'validation'})


def test_attach_without_a_sim_times_out_with_advice(namespace):
    start = time.monotonic()
    with pytest.raises(SimUnavailableError, match='ros2 run nav_sim sim_node'):
        NavigationEnv(namespace=namespace, sim='attach', sim_timeout=2.0)
    # about the 2 s sim_timeout; 8 s more is the margin for a loaded 2-core machine
    assert time.monotonic() - start < 10


def test_auto_attaches_to_a_running_sim(namespace):
    with SimProcess(namespace=namespace) as sim:
        env = NavigationEnv(namespace=namespace, sim='auto', sim_timeout=20.0, probe_timeout=10)
        try:
            assert env._sim_process is None
            env.reset(seed=1)
        finally:
            env.close()
        assert sim.alive()


def test_a_vanished_sim_is_a_clear_error_not_a_hang(namespace):
    own = NavigationEnv(namespace=namespace, sim='embedded', sim_timeout=3.0)
    try:
        own.reset(seed=108)
        own._sim_process.process.send_signal(signal.SIGKILL)
        start = time.monotonic()
        with pytest.raises(SimUnavailableError, match='nav_sim'):
            for _ in range(100):
                own.step(0)
        # about the 3 s sim_timeout (a killed sim stays in the graph a while, so the first step
        # waits that long); 2 s more is the margin for a loaded 2-core machine, while a second
        # such wait would take 6 s
        assert time.monotonic() - start < 5
    finally:
        own.close()


def test_close_reaps_the_embedded_sim(namespace):
    own = NavigationEnv(namespace=namespace, sim='embedded')
    process = own._sim_process.process
    own.close()
    assert process.poll() is not None


def test_render_returns_the_native_camera_image(namespace):
    own = NavigationEnv(namespace=namespace, sim='embedded', render_mode='rgb_array')
    try:
        obs, _ = own.reset(seed=109)
        frame = own.render()
        assert frame.shape == (96, 128, 3) and frame.dtype == np.uint8
        assert abs(float(frame.mean()) - float(obs.mean())) < 2.0
    finally:
        own.close()


@pytest.mark.parametrize('options', [{}, {'scenario_seed': 2**64}])
@pytest.mark.parametrize('seed', [2**64, 2**63, -1])
def test_seeds_outside_the_sim_range_are_a_clear_error(env, seed, options):
    with pytest.raises(ScenarioError, match=r'seed must be in \[0, 2\*\*63\), got '):
        env.reset(seed=seed, options=options)  # an opaque SystemError from rclpy before
    with pytest.raises(ScenarioError, match=r'seed must be in \[0, 2\*\*63\), got 1844'):
        env.reset(seed=1, options={'scenario_seed': 2**64})
    assert env.reset(seed=2**63 - 1)[1]['seed'] == 2**63 - 1


def _refusal(**settings: object) -> str:
    """Connect an env and run episodes until it refuses to work with two sims; the reason.

    A new client discovers the sims of a namespace within seconds: it refuses as soon as it
    sees a second one (when it connects, at a reset, or when frames of two worlds arrive).
    """
    env = None

    def an_episode() -> bool:
        env.reset(seed=1)
        env.step(1)
        return False  # until SimConflictError

    try:
        env = NavigationEnv(**settings)
        wait_until(an_episode, 60.0, f'an env with {settings} refusing two sims in one '
                   'namespace', interval=0)
    except SimConflictError as exc:
        return str(exc)
    finally:
        if env is not None:
            env.close()


def _refused_by_the_sim(client: SimClient) -> str:
    """Call reset until the sim refuses it, having discovered the other sim and its name."""
    def refusal() -> str | None:
        response = client._call(client.cli_reset, Trigger.Request(), 'reset')
        if not response.success and '_UNKNOWN_' not in response.message:
            return response.message
        client.spin_until(lambda: False, 0.1)  # discovery takes its time
        return None

    return wait_until(refusal, 60.0, 'the sims seeing each other', interval=0)


def test_two_sims_in_one_namespace_are_refused_naming_them(namespace):
    settings = {'namespace': namespace, 'sim_timeout': 30.0, 'probe_timeout': 10.0}
    conflict = rf"^{CONFLICT}: 2 nodes in namespace '{namespace}' "
    with SimProcess(namespace=namespace) as first:
        env = NavigationEnv(sim='attach', **settings)
        try:
            env.reset(seed=1)
            with SimProcess(namespace=namespace, params={'train_bank_seed': 1001}):
                # the sim refuses to reset next to another one, naming both
                message = _refused_by_the_sim(env.client)
                assert re.match(conflict, message), message
                assert f'({namespace}/sim_node, {namespace}/sim_node)' in message
                # so does the attached env (before: observations from both worlds)
                with pytest.raises(SimConflictError, match=conflict):
                    env.reset(seed=1)
                for sim in ('attach', 'auto'):
                    assert re.match(conflict, _refusal(sim=sim, **settings))
                assert re.search(f"{conflict}|^namespace '{namespace}' already has a nav_sim",
                                 _refusal(sim='embedded', **settings))
                # and it left no third sim there
                assert env.client.spin_until(lambda: len(env.client.sim_nodes()) == 2, 30.0)
            assert env.client.spin_until(lambda: len(env.client.sim_nodes()) == 1, 30.0)
            env.reset(seed=1)  # one sim again: fine
        finally:
            env.close()
        # 'embedded' into a namespace that has one sim is refused too
        assert f"namespace '{namespace}' already has a nav_sim" in _refusal(sim='embedded',
                                                                             **settings)
        assert first.alive()
