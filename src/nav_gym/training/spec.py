"""Which learner a run trains: the TD target and the components, each a flag of its own.

Light imports only (no torch).  :class:`LearnerSpec` names the learner, its fields are
:class:`nav_gym.training.config.TrainConfig`'s too, and :mod:`nav_gym.training.learner` builds
it.  A model saves its spec, so a resumed run trains the same learner.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from nav_gym.errors import TrainConfigError
from nav_sim.core.config import (
    AT_LEAST_ONE,
    FRACTION,
    NON_NEGATIVE,
    Bounds,
    check_bounds,
    setting,
)

#: the components' flags (LearnerSpec fields), each with its value that turns the component off
COMPONENTS = {'n_steps': 1, 'dueling': False, 'augment_shift': 0, 'augment_colour': 0.0,
              'prioritized_replay': False, 'frame_stack': 1, 'previous_action': False,
              'aux_depth': 0.0, 'munchausen': False, 'reset_interval': 0, 'recurrent': 0}
#: the memory components (both on by default) turned off: the agent sees the latest frame alone
WITHOUT_MEMORY = {name: COMPONENTS[name] for name in ('frame_stack', 'previous_action')}
#: settings whose default has changed: a run whose config (or a checkpoint whose LearnerSpec)
#: does not name one, saved before the setting existed, trained with this value (SB3's DQN,
#: one-step targets, no memory and no resets at SB3's replay ratio)
LEGACY_DEFAULTS = {'double_q': False, 'n_steps': 1, 'frame_stack': 1, 'previous_action': False,
                   'reset_interval': 0, 'gradient_steps': 1}


@dataclass(frozen=True)
class LearnerSpec:
    """Which learner a run trains: the TD target and the components (TrainConfig's fields).

    Each component has a published basis and is off at its value in :data:`COMPONENTS`.  The
    default learner is SB3's DQN with Double DQN targets, 3-step returns, a 4-frame stack with
    the previous action, and resets every 20,000 steps at TrainConfig's replay ratio of 2
    (``gradient_steps``; each adopted in docs/experiments.md); every component off is SB3's
    DQN with Double DQN targets, and ``double_q: false`` with every component off is SB3's DQN
    untouched, the workshop's learner (config/workshop.yaml, which also sets
    ``gradient_steps: 1``).  :mod:`nav_gym.training.learner` builds it.
    """

    double_q: bool = setting(True, 'Double DQN targets (van Hasselt et al. 2016): the online '
                             "network picks the next action, the target network values it; false: "
                             "SB3's DQN target (with n_steps 1 and every other component off, "
                             "the workshop's learner, SB3's DQN exactly: config/workshop.yaml)")
    n_steps: int = setting(3, "n-step returns (SB3's NStepReplayBuffer; Sutton 1988, Rainbow); "
                           '1: one-step targets', AT_LEAST_ONE)
    dueling: bool = setting(False, 'a dueling head, Q = V + A - mean(A) (Wang et al. 2016)')
    augment_shift: int = setting(0, 'shift every sampled observation at random by up to this '
                                 'many pixels, edges replicated (DrQ, Kostrikov et al. 2021; '
                                 'RAD); 0: off', NON_NEGATIVE)
    augment_colour: float = setting(0.0, 'jitter the colours of every sampled observation: '
                                    'brightness, contrast and saturation each scaled by a '
                                    'factor from [1 - s, 1 + s], the hue turned by up to s x '
                                    '100 degrees (RAD, Laskin et al. 2020); the frames of one '
                                    'stack alike; 0: off', Bounds(0.0, 1.0, high_open=True))
    prioritized_replay: bool = setting(False, 'proportional prioritized replay with importance '
                                       'weights (Schaul et al. 2016)')
    frame_stack: int = setting(4, "the agent's memory: its last k camera frames stacked, the "
                               "episode's first frame standing in before its start, rebuilt "
                               'from a replay buffer of single frames (DRQN, Hausknecht & Stone '
                               '2015, compare a recurrence with a stack of the same length); '
                               '1: the frame alone', Bounds(1, 16))
    previous_action: bool = setting(True, "the agent's memory of what it did: the action that "
                                    'led to the latest frame as one-hot input planes after the '
                                    'frames, none at an episode start (Mirowski et al. 2017)')
    aux_depth: float = setting(0.0, 'weight of an auxiliary loss: a linear head on the online '
                               "network's features predicts the camera's coarse depth of each "
                               "sampled observation (info['depth'], a 4 x 16 grid; Mirowski et "
                               'al. 2017, UNREAL), a training signal only: acting never uses '
                               'the head; 0: off', NON_NEGATIVE)
    munchausen: bool = setting(False, 'Munchausen DQN (Vieillard et al. 2020): the target adds '
                               "the scaled log-policy of the action taken (the target network's "
                               'softmax, tau 0.03, alpha 0.9, clip -1), bootstraps from the soft '
                               'value, and replaces Double DQN (set double_q: false)')
    reset_interval: int = setting(20_000, 'every this many env steps, re-initialise the fully '
                                  'connected layers of the online Q-network (the convolutions '
                                  'kept) and forget their optimiser state: resets against the '
                                  'primacy bias, which allow a higher replay ratio '
                                  '(gradient_steps; Nikishin et al. 2022); 0: off', NON_NEGATIVE)
    recurrent: int = setting(0, 'a recurrent Q-network: an LSTM of this many units reads the '
                             "CNN features of each frame of the agent's frame_stack window, "
                             "oldest first from a zero state (the frames before the latest "
                             'are its burn-in), and its last output feeds the Q head (DRQN, '
                             'Hausknecht & Stone 2015; R2D2, Kapturowski et al. 2019); needs '
                             'frame_stack > 1; 0: off', Bounds(0, 1024))
    priority_alpha: float = setting(0.6, 'prioritized replay: priority = (|TD error| + '
                                    'eps)^alpha', FRACTION)
    priority_beta: float = setting(0.4, 'prioritized replay: importance-weight exponent at the '
                                   'start, annealed linearly to 1', FRACTION)

    def __post_init__(self) -> None:
        """Refuse values the learner cannot use (TrainConfigError): each field's bounds."""
        check_bounds(self, TrainConfigError)
        if self.munchausen and self.double_q:
            raise TrainConfigError('munchausen replaces Double DQN targets: set double_q: false')
        if self.recurrent and self.frame_stack < 2:
            raise TrainConfigError('recurrent reads the frame_stack window: set frame_stack to '
                                   '2 or more')

    @property
    def memory(self) -> bool:
        """Tell whether the agent keeps a history (a frame stack or the previous action)."""
        return self.frame_stack > 1 or self.previous_action

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickle a checkpoint's spec: a field it was saved without takes its value then.

        Unpickling would otherwise read the class's default of today for it (a checkpoint from
        before ``frame_stack`` would become a 4-frame learner).
        """
        then = {name: LEGACY_DEFAULTS.get(name, field.default)
                for name, field in LEARNER_FIELDS.items()}
        self.__dict__.update({**then, **state})

    @property
    def vanilla(self) -> bool:
        """Tell whether this is SB3's DQN untouched (no Double DQN target, no component)."""
        return not self.double_q and all(
            getattr(self, name) == off for name, off in COMPONENTS.items())

    def describe(self) -> str:
        """Name the learner as the report and Sweep.md write it."""
        parts = ['DQN (SB3) with Double DQN targets (van Hasselt et al. 2016)'
                 if self.double_q else 'Munchausen DQN (Vieillard et al. 2020) on SB3'
                 if self.munchausen else 'DQN (SB3)']
        parts.extend(text for on, text in (
            (self.n_steps > 1, f'{self.n_steps}-step returns'),
            (self.dueling, 'a dueling head (Wang et al. 2016)'),
            (self.augment_shift, f'random shifts of up to {self.augment_shift} px (DrQ, '
                                 'Kostrikov et al. 2021)'),
            (self.augment_colour, f'colour jitter of strength {self.augment_colour:g} (RAD, '
                                  'Laskin et al. 2020)'),
            (self.frame_stack > 1, f'a {self.frame_stack}-frame stack (Hausknecht & Stone 2015)'),
            (self.recurrent, f'an LSTM of {self.recurrent} units over the window (Hausknecht & '
                             'Stone 2015)'),
            (self.previous_action, 'the previous action as input (Mirowski et al. 2017)'),
            (self.aux_depth, f'an auxiliary depth loss of weight {self.aux_depth:g} (Mirowski et '
                             'al. 2017)'),
            (self.reset_interval, f'resets of the fully connected layers every '
                                  f'{self.reset_interval} steps (Nikishin et al. 2022)'),
            (self.prioritized_replay, f'prioritized replay (Schaul et al. 2016, alpha '
                                      f'{self.priority_alpha}, beta {self.priority_beta} to 1)'),
        ) if on)
        return ', '.join(parts)


LEARNER_FIELDS = {f.name: f for f in dataclasses.fields(LearnerSpec)}


def learner_of(settings: dict[str, Any]) -> LearnerSpec:
    """Return the learner a mapping of training settings names (its other keys ignored)."""
    return LearnerSpec(**{k: v for k, v in settings.items() if k in LEARNER_FIELDS})
