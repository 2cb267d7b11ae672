"""A trained policy outside the env: its model, actions and decisions (no ROS).

What the policy node (:mod:`nav_gym.policy_node`, ``ros2 run nav_gym policy``) calls, so that
the node is a thin adapter and all of this is testable without a graph:

* :func:`load_policy`: the model and what its run says about acting.  ``model`` is a run
  directory (its ``final_model.zip``) or a checkpoint ``.zip``; the run's ``config.yaml`` (of
  the directory, or of the run the checkpoint lies in) gives each action's velocities
  (:func:`nav_gym.actions.action_twists`) and the control period.  A ``.zip`` outside any run
  directory acts with the training defaults (:class:`nav_gym.train_config.TrainConfig`:
  forward 0.12 m/s, turns 0.03 m/s at +-0.75 rad/s, 0.512 s periods), and says so.
  ``policy='servo'`` is the image-only servo baseline (:mod:`nav_gym.servo`), which needs no
  model (a given one only lends its run's actions).
* :class:`Controller`: the newest image in, a command out at every decision.  The observation
  is the env's own (:func:`nav_gym.observation.image_msg_to_observation`); a DQN takes its
  greedy action, the one ``predict(deterministic=True)`` takes, from one forward pass that also
  gives the Q-values.  Without an image newer than ``image_timeout`` the command is a stop.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from nav_gym.actions import ACTION_NAMES, action_twists
from nav_gym.errors import ObservationError, PolicyModelError, TrainConfigError
from nav_gym.observation import image_msg_to_observation
from nav_gym.run_dir import FINAL_MODEL, is_run_dir, load_config
from nav_gym.servo import servo_act, servo_band
from nav_gym.train_config import TrainConfig
from nav_sim.config import SimConfig, setting
from nav_sim.errors import ConfigError

POLICIES = ('dqn', 'servo')
STOP = -1  # the action of a stop command (no usable image): zero velocity


@dataclass(frozen=True)
class PolicyConfig:
    """Parameters of the policy node (``config/policy.yaml`` lists them with their defaults)."""

    model: str = setting('', "the trained model: a run directory (its final_model.zip) or a "
                         "checkpoint .zip; its run's config.yaml gives the actions ('' only "
                         'with policy servo)')
    policy: str = setting('dqn', "'dqn': the model's greedy action; 'servo': the image-only "
                          'servo baseline (turns toward green pixels; needs no model)')
    period: float = setting(0.0, 'decision period in wall-clock seconds (0: the control period '
                            "of the model's run, 0.512 s by default; at a sim's realtime_rate R "
                            'use ctrl_dt / R)')
    image_timeout: float = setting(0.0, 'publish zero velocity while no image newer than this '
                                   '(wall-clock seconds) has arrived (0: two periods)')
    device: str = setting('cpu', "torch device of the model: 'cpu' or 'cuda'")

    def __post_init__(self) -> None:
        """Refuse values the node cannot run with (ConfigError)."""
        if self.policy not in POLICIES:
            raise ConfigError(f'policy must be one of {list(POLICIES)}, got {self.policy!r}')
        if self.policy == 'dqn' and not self.model:
            raise ConfigError('policy dqn needs a model: -p model:=RUN_DIR (or a .zip); or use '
                              '-p policy:=servo')
        for name in ('period', 'image_timeout'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'{name} must be a finite number of seconds >= 0 (0: the '
                                  f'default), got {value!r}')


#: every policy node parameter and its declared type
PARAMETER_TYPES = {f.name: type(f.default) for f in dataclasses.fields(PolicyConfig)}


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
    """A policy plug-in: an action (and the Q-values, if it has them) per observation."""

    def act(self, observation: np.ndarray) -> tuple[int, tuple[float, ...] | None]:
        """Choose an action for one (3, 84, 84) uint8 observation."""
        ...


class DQNActor:
    """A frozen DQN checkpoint: the greedy action and its Q-values from one forward pass."""

    def __init__(self, path: Path, device: str = 'cpu') -> None:
        """Load the checkpoint at ``path`` (any of the project's learners) onto ``device``."""
        import torch  # only a DQN needs torch (the servo starts without it)

        from nav_gym.learner import load_checkpoint
        self.path = path
        self._torch = torch
        try:
            self.model = load_checkpoint(path, device=device)
        except Exception as exc:  # SB3 and torch raise many kinds for a bad file
            raise PolicyModelError(f'cannot read the model {path} ({type(exc).__name__}: '
                                   f'{exc})') from None
        self.model.policy.set_training_mode(False)

    def act(self, observation: np.ndarray) -> tuple[int, tuple[float, ...]]:
        """Return argmax Q (what ``predict(deterministic=True)`` returns) and the Q-values."""
        tensor, _ = self.model.policy.obs_to_tensor(observation)
        with self._torch.no_grad():
            q_values = self.model.q_net(tensor)[0].cpu().numpy()
        return int(np.argmax(q_values)), tuple(round(float(q), 6) for q in q_values)


class ServoActor:
    """The image-only servo (:mod:`nav_gym.servo`) for one set of actions and camera."""

    def __init__(self, acting: Acting, turn_rate: float) -> None:
        """Make the servo whose 'centred' band fits one turn step of these actions."""
        self.band = servo_band(turn_rate, acting.control_period, acting.hfov_deg)

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
        raise PolicyModelError(f'model {path} not found: give a run directory or a checkpoint '
                               '.zip')
    return path


def run_of(checkpoint: Path) -> Path | None:
    """Return the run directory a checkpoint lies in (its folder or ``checkpoints/``'s parent)."""
    for folder in (checkpoint.parent, checkpoint.parent.parent):
        if is_run_dir(folder):
            return folder
    return None


def load_policy(config: PolicyConfig) -> tuple[Actor, Acting]:
    """Return the actor and how it acts; raise PolicyModelError saying what is wrong."""
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
        return ServoActor(acting, train.turn_rate), acting
    assert checkpoint is not None
    return DQNActor(checkpoint, config.device), acting


@dataclass(frozen=True)
class Command:
    """One decision: the cmd_vel to publish and what it was made of."""

    linear: float
    angular: float
    action: int                          # STOP (-1) when there is no usable image
    q_values: tuple[float, ...] | None
    stamp: Any                           # the decided image's header stamp (None: no image)
    image_age_s: float                   # wall-clock seconds since that image arrived
    inference_s: float                   # observation + network; 0 for a repeated decision
    observation: np.ndarray | None
    reason: str                          # 'decided', 'repeated', 'no image', 'stale', 'bad image'
    frame_id: str = ''                   # the decided image's frame

    @property
    def stopped(self) -> bool:
        """Tell whether this is a stop (zero velocity) for want of a usable image."""
        return self.action == STOP

    def values(self, stamp_age_s: float) -> list[float]:
        """Return the decision message's values, in ``nav_sim.interface.DECISION_FIELDS`` order."""
        q = self.q_values or ()
        q_values = [float(q[i]) if i < len(q) else math.nan for i in range(len(ACTION_NAMES))]
        return [float(self.action), self.linear, self.angular, *q_values,
                1e3 * self.image_age_s, 1e3 * stamp_age_s, 1e3 * self.inference_s]


class Controller:
    """Keep the newest image; at each decision, turn it into a command (or a stop).

    Every image is kept as it arrives and converted only when a decision uses it; a decision
    on the same image as the one before repeats that command without converting again (the
    policies are deterministic).  ``clock`` gives wall-clock seconds (injectable for tests).
    """

    def __init__(self, actor: Actor, acting: Acting, image_timeout: float,
                 clock: Any = time.monotonic) -> None:
        """Act with ``actor``; stop when the newest image is older than ``image_timeout`` s."""
        self.actor = actor
        self.twists = acting.twists
        self.image_timeout = image_timeout
        self.clock = clock
        self._image: Any = None
        self._received = -math.inf
        self._last: Command | None = None
        self._last_image: Any = None
        self.image_error = ''  # why the newest image could not be converted

    def on_image(self, msg: Any, received: float | None = None) -> None:
        """Keep ``msg`` (a sensor_msgs/Image) as the newest image, received now by default."""
        self._image = msg
        self._received = self.clock() if received is None else received

    def decide(self, now: float | None = None) -> Command:
        """Return the command for the newest image (a stop if it is missing, stale or bad).

        Raises nothing for a bad image: its command is a stop with ``reason='bad image'``, and
        :attr:`image_error` says why.
        """
        now = self.clock() if now is None else now
        msg, age = self._image, now - self._received
        if msg is None:
            return self._stop('no image', None, math.nan)
        if age > self.image_timeout:
            return self._stop('stale', msg.header, age)
        last = self._last
        if msg is self._last_image and last is not None:
            return dataclasses.replace(last, image_age_s=age, inference_s=0.0,
                                       reason=last.reason if last.stopped else 'repeated')
        start = time.perf_counter()
        try:
            observation, _ = image_msg_to_observation(msg)
        except ObservationError as exc:
            self.image_error = str(exc)
            command = self._stop('bad image', msg.header, age)
        else:
            action, q_values = self.actor.act(observation)
            linear, angular = self.twists[action]
            command = Command(linear, angular, action, q_values, msg.header.stamp, age,
                              time.perf_counter() - start, observation, 'decided',
                              msg.header.frame_id)
        self._last, self._last_image = command, msg
        return command

    def _stop(self, reason: str, header: Any, age: float) -> Command:
        if header is None:
            return Command(0.0, 0.0, STOP, None, None, age, 0.0, None, reason)
        return Command(0.0, 0.0, STOP, None, header.stamp, age, 0.0, None, reason,
                       header.frame_id)
