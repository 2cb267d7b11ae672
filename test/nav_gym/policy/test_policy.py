"""The policy node's ROS-free part: the model, its run's actions and the decisions."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from helpers import REPO, make_tiny_run
from nav_gym.env.observation import image_msg_to_observation
from nav_gym.errors import PolicyModelError
from nav_gym.policy.actors import DQNActor, load_policy
from nav_gym.policy.config import PolicyConfig
from nav_gym.policy.controller import STOP, Controller
from nav_gym.training.config import TrainConfig
from nav_sim.errors import ConfigError
from nav_sim.interface import DECISION_FIELDS


@pytest.fixture(scope='module')
def run(tmp_path_factory, spaces_only) -> Path:
    """Make a run whose actions differ from the defaults (forward 0.2 m/s, turns at 1.0 rad/s)."""
    return make_tiny_run(tmp_path_factory.mktemp('run'), spaces_only, forward_speed=0.2,
                         turn_rate=1.0, sim_params={'sim_dt': 0.016})


def image(rgb: np.ndarray, stamp_s: int = 7, encoding: str = 'rgb8') -> SimpleNamespace:
    """Return a sensor_msgs/Image look-alike of an (H, W, 3) array."""
    header = SimpleNamespace(stamp=SimpleNamespace(sec=stamp_s, nanosec=0), frame_id='cam')
    return SimpleNamespace(data=rgb.tobytes(), height=rgb.shape[0], width=rgb.shape[1],
                           encoding=encoding, step=rgb.shape[1] * 3, header=header)


class Counting:
    """An actor that counts its calls and always drives forward."""

    name = 'counting'

    def __init__(self) -> None:
        self.observations: list[np.ndarray] = []
        self.episodes: list[int | None] = []

    def begin_episode(self, seed):
        self.episodes.append(seed)

    def act(self, observation):
        self.observations.append(observation)
        return 1, (0.1, 0.5, 0.2)


def test_the_controller_begins_its_actors_first_episode():
    actor = Counting()
    controller(actor)
    assert actor.episodes == [None] and actor.observations == []


def controller(actor=None, timeout: float = 1.0):
    clock = SimpleNamespace(now=100.0)
    _, acting = load_policy(PolicyConfig(policy='servo'))
    return Controller(actor or Counting(), acting, timeout, clock=lambda: clock.now), clock


def test_a_run_directory_gives_its_final_model_and_its_own_actions(run):
    actor, acting = load_policy(PolicyConfig(model=str(run)))
    assert isinstance(actor, DQNActor) and actor.path == run / 'final_model.zip'
    assert acting.twists == ((0.03, 1.0), (0.2, 0.0), (0.03, -1.0))
    assert acting.control_period == pytest.approx(16 * 0.016)
    assert acting.source == f'{run}/config.yaml'


def test_a_checkpoint_in_a_run_acts_as_its_run_and_a_bare_one_as_the_defaults(run, tmp_path):
    checkpoint = run / 'checkpoints' / 'dqn_32_steps.zip'
    _, acting = load_policy(PolicyConfig(model=str(checkpoint)))
    assert acting.twists[1] == (0.2, 0.0)
    bare = tmp_path / 'model.zip'
    bare.write_bytes(checkpoint.read_bytes())
    _, acting = load_policy(PolicyConfig(model=str(bare)))
    defaults = TrainConfig()
    assert acting.twists[1] == (defaults.forward_speed, 0.0)
    assert acting.control_period == pytest.approx(0.512)
    assert 'training defaults' in acting.source


def test_the_greedy_action_is_what_predict_takes_and_comes_with_its_q_values(run):
    actor, _ = load_policy(PolicyConfig(model=str(run)))
    rng = np.random.default_rng(0)
    actor.begin_episode(0)
    for _ in range(5):
        obs = rng.integers(0, 256, (3, 84, 84), dtype=np.uint8)
        action, q_values = actor.act(obs)
        network_input = actor.memory.history.observation()  # the default learner's stack
        predicted, _ = actor.model.predict(network_input, deterministic=True)
        assert action == int(predicted) == int(np.argmax(q_values)) and len(q_values) == 3


def test_evaluation_and_the_policy_node_act_through_one_protocol(run):
    """The evaluation's DQN is the node's DQN actor: the same greedy step, one episode hook."""
    from nav_eval.evaluation.policies import DQNPolicy, ExploringDQNPolicy, ServoPolicy
    from nav_gym.policy.actors import DQNActor, ServoActor
    node_actor, _ = load_policy(PolicyConfig(model=str(run)))
    evaluated = DQNPolicy(run / 'final_model.zip')
    assert isinstance(evaluated, DQNActor) and ServoPolicy is ServoActor
    assert type(evaluated).act is DQNActor.act  # one definition of greedy acting
    rng = np.random.default_rng(1)
    for actor in (node_actor, evaluated, ExploringDQNPolicy(run / 'final_model.zip', 0.0)):
        actor.begin_episode(7)
    obs = rng.integers(0, 256, (3, 84, 84), dtype=np.uint8)
    assert node_actor.act(obs) == evaluated.act(obs)


@pytest.mark.parametrize(('model', 'match'), [
    ('/no/such/run', 'model /no/such/run not found'),
    ('EMPTY_DIR', 'has no final_model.zip'),
    ('CORRUPT', 'cannot read the model'),
])
def test_a_model_that_cannot_be_read_is_a_clear_error(tmp_path, model, match):
    if model == 'EMPTY_DIR':
        model = str(tmp_path)
    elif model == 'CORRUPT':
        model = str(tmp_path / 'bad.zip')
        Path(model).write_bytes(b'not a zip')
    with pytest.raises(PolicyModelError, match=match):
        load_policy(PolicyConfig(model=model))


@pytest.mark.parametrize(('values', 'match'), [
    ({'policy': 'ppo'}, 'policy must be one of'),
    ({'policy': 'dqn'}, 'policy dqn needs a model'),
    ({'policy': 'servo', 'period': -1.0}, 'period must be >= 0, got -1.0'),
    ({'policy': 'servo', 'image_timeout': math.inf}, 'image_timeout must be >= 0, got inf'),
])
def test_settings_the_node_cannot_run_with_are_refused(values, match):
    with pytest.raises(ConfigError, match=match):
        PolicyConfig(**values)


def test_no_image_and_a_stale_image_stop_the_robot():
    ctl, clock = controller(timeout=1.0)
    command = ctl.decide()
    assert command.stopped and command.reason == 'no image' and command.linear == 0.0
    ctl.on_image(image(np.zeros((96, 128, 3), np.uint8)))
    clock.now += 0.9
    assert ctl.decide().action == 1
    clock.now += 0.2   # 1.1 s since the image arrived
    command = ctl.decide()
    assert command.stopped and command.reason == 'stale'
    assert (command.linear, command.angular) == (0.0, 0.0)
    assert command.image_age_s == pytest.approx(1.1)


def test_each_image_is_converted_once_with_the_envs_own_function():
    actor = Counting()
    ctl, clock = controller(actor)
    rng = np.random.default_rng(1)
    msg = image(rng.integers(0, 256, (60, 90, 3), dtype=np.uint8))
    ctl.on_image(msg)
    first = ctl.decide()
    again = ctl.decide()
    assert first.reason == 'decided' and again.reason == 'repeated'
    assert again.inference_s == 0.0 and len(actor.observations) == 1
    assert np.array_equal(actor.observations[0], image_msg_to_observation(msg)[0])
    assert (first.linear, first.angular) == ctl.twists[1]


def test_an_unsupported_encoding_is_a_stop_with_the_reason():
    ctl, _ = controller()
    ctl.on_image(image(np.zeros((4, 4, 3), np.uint8), encoding='16UC1'))
    command = ctl.decide()
    assert command.stopped and command.reason == 'bad image'
    assert "unsupported image encoding '16UC1'" in ctl.image_error


def test_the_decision_message_values_follow_the_field_names():
    ctl, _ = controller()
    ctl.on_image(image(np.zeros((8, 8, 3), np.uint8)))
    values = dict(zip(DECISION_FIELDS, ctl.decide().values(0.25), strict=True))
    assert values['action'] == 1 and values['q_forward'] == 0.5
    assert values['linear'] == ctl.twists[1][0] and values['stamp_age_ms'] == 250.0
    stop = dict(zip(DECISION_FIELDS, controller()[0].decide().values(math.nan), strict=True))
    assert stop['action'] == STOP and math.isnan(stop['q_left'])


def test_the_params_file_lists_every_parameter_with_its_default():
    import dataclasses

    import yaml
    from ament_index_python.packages import get_package_share_directory
    share = Path(get_package_share_directory('nav_gym'))
    params = yaml.safe_load((share / 'config' / 'policy.yaml').read_text())
    fields = dataclasses.fields(PolicyConfig)
    assert params['/**']['ros__parameters'] == {f.name: f.default for f in fields}
    assert (REPO / 'config' / 'policy.yaml').read_text() == \
        (share / 'config' / 'policy.yaml').read_text()


def test_a_stale_image_stop_and_an_explicit_start_begin_the_actors_memory():
    """After a gap in the camera, what the robot saw before is no history to act on."""
    actor = Counting()
    ctl, clock = controller(actor, timeout=1.0)
    ctl.on_image(image(np.zeros((96, 128, 3), np.uint8)))
    assert ctl.decide().reason == 'decided' and actor.episodes == [None]
    clock.now += 1.5
    assert ctl.decide().reason == 'stale' and ctl.decide().reason == 'stale'
    assert actor.episodes == [None, None]  # once per gap
    ctl.on_image(image(np.zeros((96, 128, 3), np.uint8)))
    assert ctl.decide().reason == 'decided'
    ctl.begin_episode(7)  # the node's policy/begin_episode service
    assert actor.episodes == [None, None, 7]
    # the newest image is the episode before's: a stop until the episode's first image
    assert ctl.decide().reason == 'new episode' and ctl.decide().stopped
    assert len(actor.observations) == 2
    ctl.on_image(image(np.zeros((96, 128, 3), np.uint8)))
    assert ctl.decide().reason == 'decided'
    assert len(actor.observations) == 3


def test_a_reset_event_begins_the_episode_at_its_frames_stamp_whichever_comes_first():
    """The sim's reset event and its frame share a stamp but travel on two topics."""
    actor = Counting()
    ctl, _ = controller(actor)
    old = image(np.zeros((96, 128, 3), np.uint8), stamp_s=4)
    frame = image(np.ones((96, 128, 3), np.uint8), stamp_s=5)

    def before_5s(msg) -> bool:  # noqa: ANN001 - what the node passes: stamp < the event's
        return msg.header.stamp.sec < 5

    ctl.on_image(old)
    assert ctl.decide().reason == 'decided'
    ctl.begin_episode(3, before_5s)  # the event first: the old image is not acted on
    assert ctl.decide().reason == 'new episode' and len(actor.observations) == 1
    ctl.on_image(frame)
    assert ctl.decide().reason == 'decided' and len(actor.observations) == 2
    ctl.begin_episode(4, before_5s)  # the frame first, then its event: decided afresh
    assert ctl.decide().reason == 'decided' and len(actor.observations) == 3
    assert actor.episodes == [None, 3, 4]
