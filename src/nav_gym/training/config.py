"""Training configuration: the learner, the workshop's DQN settings and the run's whole EnvConfig.

Overridable from YAML and the command line; the effective configuration is saved with each run.
Light imports only (no torch): :mod:`nav_gym.training.spec` names the learner,
:mod:`nav_gym.training.learner` builds it.  Checkpoints saved before the spec had its own module
pickle it as ``nav_gym.training.config.LearnerSpec``, which this module imports.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import yaml

from nav_gym.env.config import EnvConfig, parse_mapping
from nav_gym.errors import TrainConfigError
from nav_gym.training.spec import LEARNER_FIELDS, LearnerSpec, learner_of
from nav_sim.core.config import (
    AT_LEAST_ONE,
    FRACTION,
    NON_NEGATIVE,
    POSITIVE,
    Bounds,
    SimConfig,
    check_bounds,
    convert,
    setting,
)
from nav_sim.core.world_file import world_settings
from nav_sim.errors import ConfigError
from nav_sim.interface import full_name
from nav_sim.paths import plain_name_problem
from nav_sim.ros.process import typed_params

#: the most parallel sims a run may ask for (each is a process with its own renderer)
MAX_ENVS = 64
_ENV_FIELDS = {f.name: f for f in dataclasses.fields(EnvConfig)}
#: the torch devices a run may name
DEVICE = re.compile(r'auto|cpu|cuda(:\d+)?')


def vector_schedule(train_freq: int, gradient_steps: int, n_envs: int) -> tuple[int, int]:
    """Return SB3's ``(train_freq, gradient_steps)`` that keep the replay ratio with N envs.

    SB3 counts ``train_freq`` in vector steps (N env steps each).  The ratio of gradient steps
    to env steps, ``gradient_steps / train_freq``, stays the configured one: with SB3's 1/4
    (``gradient_steps: 1``), two envs update once every 2 vector steps, four envs once every
    step, eight envs twice every step.  One env keeps the configured pair as it is.
    """
    if n_envs == 1:
        return train_freq, gradient_steps
    per_vector_step = Fraction(gradient_steps, train_freq) * n_envs
    return per_vector_step.denominator, per_vector_step.numerator


def _env(name: str) -> Any:
    """Declare a field as the EnvConfig field ``name`` declares it (default, help, bounds)."""
    return dataclasses.field(default=_ENV_FIELDS[name].default,
                             metadata=_ENV_FIELDS[name].metadata)


def _learner(name: str) -> Any:
    """Declare a field as the LearnerSpec field ``name`` declares it (default, help, bounds)."""
    return dataclasses.field(default=LEARNER_FIELDS[name].default,
                             metadata=LEARNER_FIELDS[name].metadata)


@dataclass(frozen=True)
class TrainConfig:
    """The learner on Monitor(NavigationEnv): :class:`LearnerSpec`'s, at the workshop settings.

    Double DQN targets, 3-step returns, a 4-frame stack with the previous action, and resets
    every 20,000 steps at two gradient steps per update; config/workshop.yaml is the workshop's.
    """

    total_timesteps: int = setting(50_000, 'environment steps to train for', AT_LEAST_ONE)
    learning_rate: float = setting(1e-4, 'optimiser step size', POSITIVE)
    buffer_size: int = setting(50_000, 'replay buffer capacity (transitions)', AT_LEAST_ONE)
    learning_starts: int = setting(2_000, 'steps collected before gradient updates begin',
                                   NON_NEGATIVE)
    batch_size: int = setting(32, 'transitions per gradient step', AT_LEAST_ONE)
    gamma: float = setting(0.99, 'discount factor', Bounds(0.0, 1.0, low_open=True))
    train_freq: int = setting(4, 'environment steps between gradient updates (SB3 default)',
                              AT_LEAST_ONE)
    gradient_steps: int = setting(2, "gradient steps per update: a replay ratio twice SB3's "
                                  "default (1), with reset_interval's resets (Nikishin et al. "
                                  '2022)', AT_LEAST_ONE)
    target_update_interval: int = setting(1_000, 'steps between target-network updates',
                                          AT_LEAST_ONE)
    exploration_fraction: float = setting(0.25, 'fraction of training over which epsilon decays',
                                          Bounds(0.0, 1.0, low_open=True))
    exploration_initial_eps: float = setting(1.0, 'initial epsilon (SB3 default)', FRACTION)
    exploration_final_eps: float = setting(0.05, 'final epsilon', FRACTION)
    seed: int = setting(9, 'seed of DQN, the env and its scenario sequence',
                        Bounds(0, 2**32 - 1))
    n_envs: int = setting(1, 'sims trained on at once, each its own process and namespace, '
                          'stepped concurrently (1: the workshop protocol; every env has its '
                          'own scenario stream; the replay ratio train_freq:gradient_steps is '
                          'kept per env step)', Bounds(1, MAX_ENVS))
    double_q: bool = _learner('double_q')
    n_steps: int = _learner('n_steps')
    dueling: bool = _learner('dueling')
    augment_shift: int = _learner('augment_shift')
    augment_colour: float = _learner('augment_colour')
    prioritized_replay: bool = _learner('prioritized_replay')
    frame_stack: int = _learner('frame_stack')
    previous_action: bool = _learner('previous_action')
    aux_depth: float = _learner('aux_depth')
    munchausen: bool = _learner('munchausen')
    reset_interval: int = _learner('reset_interval')
    recurrent: int = _learner('recurrent')
    priority_alpha: float = _learner('priority_alpha')
    priority_beta: float = _learner('priority_beta')
    checkpoint_freq: int = setting(10_000, 'steps between checkpoints (all are kept)',
                                   AT_LEAST_ONE)
    save_replay_buffer: bool = setting(True, 'save the replay buffer with checkpoints (for '
                                       '--resume)')
    keep_replay_buffer: bool = setting(False, 'keep checkpoints/replay_buffer.pkl when the run '
                                       'finishes (it is only needed to resume; ~2 GB at 50k)')
    device: str = setting('auto', "torch device: 'auto', 'cpu' or 'cuda'")
    runs_dir: str = setting('runs', 'directory that holds one sub-directory per run')
    run_name: str = setting('', "run directory name ('' = dqn_<date>_<time>)")
    # the env's settings, as EnvConfig defines them (the run's whole EnvConfig: env_config())
    split: str = _env('split')
    max_episode_steps: int = _env('max_episode_steps')
    namespace: str = _env('namespace')
    sim: str = _env('sim')
    sim_timeout: float = _env('sim_timeout')
    probe_timeout: float = _env('probe_timeout')
    cmd_vel_stamped: bool = _env('cmd_vel_stamped')
    forward_speed: float = _env('forward_speed')
    turn_rate: float = _env('turn_rate')
    turn_speed: float = _env('turn_speed')
    progress_weight: float = _env('progress_weight')
    step_penalty: float = _env('step_penalty')
    goal_reward: float = _env('goal_reward')
    collision_penalty: float = _env('collision_penalty')
    sim_params: dict = _env('sim_params')

    def __post_init__(self) -> None:
        """Check the values (a clear TrainConfigError for a bad one), before anything starts.

        Each field's bounds (its declaration states them), then the rules between fields, the
        run's name, the device, the learner's and the env's own checks.
        """
        check_bounds(self, TrainConfigError)
        if self.buffer_size < self.batch_size:
            raise TrainConfigError(f'buffer_size must be >= batch_size ({self.batch_size}), got '
                                   f'{self.buffer_size}')
        if self.exploration_final_eps > self.exploration_initial_eps:
            raise TrainConfigError(
                f'exploration_final_eps must be <= exploration_initial_eps '
                f'({self.exploration_initial_eps}), got {self.exploration_final_eps}')
        if not DEVICE.fullmatch(self.device):
            raise TrainConfigError(f"device must be 'auto', 'cpu', 'cuda' or 'cuda:N', got "
                                   f'{self.device!r}')
        if self.run_name:
            problem = plain_name_problem('run_name', self.run_name)
            if problem:
                raise TrainConfigError(problem)
        self.learner()  # the learner's own checks
        if self.n_envs > 1 and self.prioritized_replay:
            raise TrainConfigError('prioritized_replay supports n_envs 1 only, got n_envs '
                                   f'{self.n_envs}')
        if self.n_envs > 1 and self.sim == 'attach':
            raise TrainConfigError(f"n_envs {self.n_envs} starts a sim per env: sim must be "
                                   "'auto' or 'embedded', not 'attach'")
        # the env's checks, and its resolved values (the absolute namespace, sim_params {}, the
        # world's episode limit)
        env = EnvConfig(**{name: getattr(self, name) for name in _ENV_FIELDS})
        object.__setattr__(self, 'namespace', env.namespace)
        object.__setattr__(self, 'sim_params', env.sim_params)
        object.__setattr__(self, 'max_episode_steps', env.max_episode_steps)

    def env_config(self, **overrides: Any) -> EnvConfig:
        """Return the run's whole EnvConfig (actions, episode limit, reward weights, sim)."""
        values = {name: getattr(self, name) for name in _ENV_FIELDS}
        values['sim_params'] = dict(self.sim_params)
        return EnvConfig(**{**values, **overrides})

    def learner(self) -> LearnerSpec:
        """Return which learner this config trains (the TD target and the components)."""
        return learner_of(dataclasses.asdict(self))

    def dqn_kwargs(self) -> dict[str, Any]:
        """Return the hyperparameters of ``DQN(...)`` this config sets.

        What the learner itself adds is :func:`nav_gym.training.learner.learner_kwargs`.
        """
        keys = ('learning_rate', 'buffer_size', 'learning_starts', 'batch_size', 'gamma',
                'train_freq', 'gradient_steps', 'target_update_interval',
                'exploration_fraction', 'exploration_initial_eps', 'exploration_final_eps',
                'seed', 'device')
        kwargs = {k: getattr(self, k) for k in keys}
        kwargs['train_freq'], kwargs['gradient_steps'] = vector_schedule(
            self.train_freq, self.gradient_steps, self.n_envs)
        return kwargs

    def env_configs(self) -> list[EnvConfig]:
        """Return the EnvConfig of each of the ``n_envs`` envs (:meth:`env_config` for one).

        With more than one, env ``i`` starts its own sim ('embedded') in the namespace
        ``<namespace>/env<i>``, or in a fresh unique one when ``namespace`` is ''.
        """
        if self.n_envs == 1:
            return [self.env_config()]
        return [self.env_config(sim='embedded',
                                namespace=full_name(self.namespace, f'env{i}')
                                if self.namespace else '')
                for i in range(self.n_envs)]

    def with_full_sim_params(self) -> TrainConfig:
        """Return this config with every simulation parameter spelled out in ``sim_params``.

        A run saves this, so what it was trained on does not change when a default changes
        later (evaluation, diagnosis and resume all read the run's config).  Node parameters
        in ``sim_params`` (e.g. ``publish_clock``) are kept, converted to their declared types.
        """
        try:
            params = typed_params(self.sim_params)  # known names, declared types
            sim = SimConfig.from_params(params)
        except ConfigError as exc:
            raise TrainConfigError(f'sim_params: {exc}') from exc
        return dataclasses.replace(self, sim_params={**params, **dataclasses.asdict(sim)})

    def in_world(self, sim_params: dict[str, Any]) -> TrainConfig:
        """Return this config with sim parameters replaced: a policy played elsewhere.

        For an evaluation in another world or look (``nav-eval-evaluate --sim-params``).  A
        new ``world`` brings its own settings: every setting the run's world or the new world
        sets (``visnav:`` customs) takes the new world's value, else its default, and the
        episode limit is the new world's; a value in ``sim_params`` wins.
        """
        try:
            given = typed_params(sim_params)
        except ConfigError as exc:
            raise TrainConfigError(f'sim_params: {exc}') from exc
        sim, steps = dict(self.sim_params), self.max_episode_steps
        old, new = (str(p.get('world', SimConfig.world)) for p in (sim, {**sim, **given}))
        if new != old:
            worlds = set(world_settings(old)) | set(world_settings(new))
            sim = {k: v for k, v in sim.items() if k not in worlds}
            steps = 0  # the new world's limit
        return dataclasses.replace(self, sim_params={**sim, **given},
                                   max_episode_steps=steps).with_full_sim_params()

    def to_yaml(self) -> str:
        """Return the config as YAML (what a run saves as config.yaml)."""
        return yaml.safe_dump(dataclasses.asdict(self), sort_keys=False)


FIELDS = {f.name: f for f in dataclasses.fields(TrainConfig)}


def coerce(values: dict[str, Any], source: str) -> dict[str, Any]:
    """Check names and convert types of overrides (YAML or command line).

    Every value goes through :func:`nav_sim.core.config.convert`, the one conversion of a setting:
    ``'4.0'`` for an int is 4, ``3.7`` is an error, a bool takes only true/false (a YAML file's
    ``yes`` is already a bool when YAML reads it; on the command line it is an error).
    """
    unknown = sorted(set(values) - set(FIELDS))
    if unknown:
        raise TrainConfigError(f'{source}: unknown setting(s) {unknown}; known: {sorted(FIELDS)}')
    out = {}
    for key, value in values.items():
        if key == 'sim_params':
            out[key] = parse_mapping(value, f'{source}: {key}')
            continue
        try:
            out[key] = convert(key, type(FIELDS[key].default), value)
        except ConfigError as exc:
            raise TrainConfigError(f'{source}: {exc}') from None
    return out


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML file of settings (checked and converted), or raise TrainConfigError."""
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8')) or {}
    except UnicodeDecodeError:
        raise TrainConfigError(f'cannot read training config {path}: not a UTF-8 text file; '
                               'it must be YAML (see config/train.yaml)') from None
    except (OSError, yaml.YAMLError) as exc:
        raise TrainConfigError(f'cannot read training config {path}: '
                               f'{" ".join(str(exc).split())}') from None
    if not isinstance(data, dict):
        raise TrainConfigError(f'{path}: expected a mapping of settings')
    return coerce(data, str(path))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """One ``--flag`` per field; only flags given on the command line override."""
    for name, f in FIELDS.items():
        flag = '--' + name.replace('_', '-')
        parser.add_argument(flag, dest=name, default=argparse.SUPPRESS, metavar='V',
                            help=f"{f.metadata['help']} (default {f.default!r})")


def build(config_file: str | None, overrides: dict[str, Any],
          base: dict[str, Any] | None = None) -> TrainConfig:
    """Return the config of defaults < ``base`` < the config file < command-line overrides."""
    values = dict(base or {})
    if config_file:
        values.update(load_yaml(config_file))
    values.update(coerce(overrides, 'command line'))
    return TrainConfig(**values)
