"""The one acting protocol (Actor) and its actors: a frozen DQN and the servo (no ROS).

:class:`Actor` is what evaluation (:mod:`nav_eval.evaluation.policies`), the closed loop and
the policy node act through: an action per observation, and ``begin_episode``, the one place
where an actor's state between decisions starts afresh.  :func:`load_policy` loads what the
policy node runs: ``model`` is a run directory (its ``final_model.zip``) or a checkpoint
``.zip`` or an export directory (``RUN/export``, :mod:`nav_gym.policy.exported`, acted on ONNX
Runtime); the run's ``config.yaml`` (of the directory, or of the run the checkpoint lies in)
gives each action's velocities (:func:`nav_gym.env.actions.action_twists`) and the control
period.  A ``.zip`` outside any run directory acts with the training defaults
(:class:`nav_gym.training.config.TrainConfig`: forward 0.12 m/s, turns 0.03 m/s at +-0.75
rad/s, 0.512 s periods), and says so.  ``policy='servo'`` is the image-only servo baseline
(:mod:`nav_gym.policy.servo`), which needs no model (a given one only lends its run's actions).
The decisions themselves are the controller's (:mod:`nav_gym.policy.controller`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from nav_gym.env.actions import action_twists
from nav_gym.env.observation import OBS_SHAPE
from nav_gym.errors import PolicyModelError, TrainConfigError
from nav_gym.policy.config import PolicyConfig
from nav_gym.policy.exported import META_FILE, OnnxActor, is_export, read_export
from nav_gym.policy.history import EpisodeMemory, GreedyActor
from nav_gym.policy.servo import servo_act, servo_band
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import FINAL_MODEL, is_run_dir, load_config
from nav_sim.core.config import SimConfig
from nav_sim.errors import ConfigError


@dataclass(frozen=True)
class Acting:
    """What a run says about acting: each action's cmd_vel, the control period, the camera."""

    twists: tuple[tuple[float, float], ...]
    control_period: float
    hfov_deg: float
    source: str  # where it came from, for the log: the run's config.yaml or the defaults

    @classmethod
    def of(cls, config: TrainConfig, source: str) -> Acting:
        """Return how a TrainConfig's env acts (its action speeds and sim settings)."""
        try:
            sim = SimConfig.from_params(config.sim_params)
        except ConfigError as exc:
            raise PolicyModelError(f'{source}: sim_params: {exc}') from None
        return cls(action_twists(config.env_config()), sim.ctrl_dt, sim.camera_hfov_deg, source)


class Actor(Protocol):
    """The one acting protocol: what evaluation, the closed loop and the policy node act with.

    ``begin_episode`` is the episode-start hook.  Whatever an actor keeps between decisions (a
    seeded random stream, a memory of earlier frames) starts afresh there: the evaluation calls
    it before each episode with the scenario's seed, the policy node at each new episode it
    learns of with the seed when it knows it, else None.  ``act`` returns an action for one
    (3, 84, 84) uint8 observation, and the Q-values it chose from where it has them.
    """

    name: str

    def begin_episode(self, seed: int | None) -> None:
        """Start an episode (of scenario ``seed``, None where unknown)."""
        ...

    def act(self, observation: np.ndarray) -> tuple[int, tuple[float, ...] | None]:
        """Choose an action for one (3, 84, 84) uint8 observation."""
        ...


class DQNActor(GreedyActor):
    """A frozen DQN: the greedy action and its Q-values from one forward pass.

    The greedy action is the one ``predict(deterministic=True)`` takes (argmax of the same
    Q-values); the network keeps no state between decisions.
    """

    name = 'dqn'

    def __init__(self, path: Path, device: str = 'cpu') -> None:
        """Load the checkpoint at ``path`` (any of the project's learners) onto ``device``.

        A learner with memory takes its last k frames (and the action before the latest): the
        actor keeps them (:class:`FrameHistory`), begun afresh at each episode start.
        """
        self.path = path
        self.hold(self.load(path, device))

    def hold(self, model: Any) -> None:
        """Act with ``model``, with a history where its network takes its last frames."""
        self.model = model
        model.policy.set_training_mode(False)
        spec = getattr(model, 'learner', None)  # SB3's own DQN has none: one frame
        n_actions = int(model.action_space.n) if getattr(spec, 'previous_action', False) else 0
        self.memory = EpisodeMemory.of(model.observation_space.shape[0], OBS_SHAPE[0],
                                       n_actions)

    @staticmethod
    def load(path: Path, device: str) -> Any:
        """Load the checkpoint for inference, or raise PolicyModelError saying what is wrong."""
        from nav_gym.training.learner import load_checkpoint  # only a DQN needs torch
        try:
            return load_checkpoint(path, device=device)
        except Exception as exc:  # SB3 and torch raise many kinds for a bad file
            raise PolicyModelError(f'cannot read the model {path} ({type(exc).__name__}: '
                                   f'{exc})') from None

    def q_values(self, network_input: np.ndarray) -> np.ndarray:
        """Return the Q-values of one input, whose argmax ``predict(deterministic=True)`` takes."""
        import torch
        tensor, _ = self.model.policy.obs_to_tensor(network_input)
        with torch.no_grad():
            return self.model.q_net(tensor)[0].cpu().numpy()


class ServoActor:
    """The image-only servo (:mod:`nav_gym.policy.servo`): a scripted baseline.

    Turns toward the green goal pixels, drives when they are centred (within ``band`` of the
    image centre, -1..1 units), else turns left.  It asks whether the task is solvable from
    single images, and measures how hard a scenario bank is without any learning.
    """

    name = 'servo'

    def __init__(self, band: float = 0.3) -> None:
        """Drive when the goal centroid is within ``band`` of the image centre."""
        self.band = band

    @classmethod
    def for_actions(cls, turn_rate: float, control_period: float,
                    hfov_deg: float) -> ServoActor:
        """Make a servo whose 'centred' band fits one turn step of these actions and camera."""
        return cls(servo_band(turn_rate, control_period, hfov_deg))

    def begin_episode(self, seed: int | None) -> None:
        """Start an episode (the servo keeps no state)."""
        return None

    def act(self, observation: np.ndarray) -> tuple[int, None]:
        """Steer toward the goal's bearing in the image; turn left while it is not in view."""
        return servo_act(observation, self.band), None


def model_file(model: str | Path) -> Path:
    """Return the checkpoint a ``model`` parameter names (a run's final model or a .zip)."""
    path = Path(model).expanduser()
    if path.is_dir():
        final = path / FINAL_MODEL
        if not final.is_file():
            raise PolicyModelError(f'{path} has no {FINAL_MODEL}: finish (or --resume) its '
                                   'training, or give a checkpoint .zip')
        return final
    if not path.is_file():
        raise PolicyModelError(f'model {path} not found: give a run directory, a checkpoint '
                               '.zip or an export directory')
    return path


def run_of(checkpoint: Path) -> Path | None:
    """Return the run directory a checkpoint lies in (its folder or ``checkpoints/``'s parent)."""
    for folder in (checkpoint.parent, checkpoint.parent.parent):
        if is_run_dir(folder):
            return folder
    return None


def load_policy(config: PolicyConfig) -> tuple[Actor, Acting]:
    """Return the actor and how it acts; raise PolicyModelError saying what is wrong.

    An export directory (``nav-gym-export``) acts on ONNX Runtime, without torch.
    """
    if config.model and is_export(config.model):
        spec = read_export(config.model)
        acting = Acting(spec.twists, spec.control_period, spec.camera_hfov_deg,
                        f'{spec.path}/{META_FILE}')
        if config.policy == 'servo':
            return ServoActor.for_actions(spec.twists[0][1], acting.control_period,
                                          acting.hfov_deg), acting
        return OnnxActor(spec), acting
    checkpoint = model_file(config.model) if config.model else None
    run = run_of(checkpoint) if checkpoint is not None else None
    try:
        train = load_config(run) if run is not None else TrainConfig()
    except TrainConfigError as exc:
        raise PolicyModelError(str(exc)) from None
    source = (f'{run}/config.yaml' if run is not None else
              'the training defaults (the model lies in no run directory)')
    acting = Acting.of(train, source)
    if config.policy == 'servo':
        return ServoActor.for_actions(train.turn_rate, acting.control_period,
                                      acting.hfov_deg), acting
    assert checkpoint is not None
    return DQNActor(checkpoint, config.device), acting


