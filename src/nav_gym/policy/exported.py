"""An exported policy (``RUN/export``) and its actor on ONNX Runtime (no torch, no SB3).

``nav-gym-export RUN`` (:mod:`nav_gym.policy.export`) writes two files into ``RUN/export``:

- ``policy.onnx``: the acting Q-network.  Input ``observation``, a (1, 3, 84, 84) uint8 image
  as the env returns it; output ``q_values``, (1, 3) float32.  The graph scales the image to
  [0, 1] itself, as SB3's ``CnnPolicy`` does, so the caller feeds the env's observation as is.
  A learner with memory (``frame_stack`` k, ``previous_action``) takes its stack instead,
  (1, 3 k [+ 3], 84, 84): the actor keeps the history between decisions with the rule the
  checkpoint's actor uses (:class:`nav_gym.policy.history.EpisodeMemory`), fed frame by frame
  and begun afresh at each ``begin_episode``.
- ``policy.json``: what the policy node needs besides the network: each action's cmd_vel, the
  control period, the camera's field of view, the observation's settings, the run's settings
  (``config``: the world, for an evaluation or the demo) and where it came from (the run, the
  checkpoint, the learner).

:func:`read_export` checks both files and says in one line what is missing or wrong;
:class:`OnnxActor` is the :class:`nav_gym.policy.actors.Actor` that acts with them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nav_gym.env.actions import ACTION_NAMES
from nav_gym.env.observation import OBS_SHAPE
from nav_gym.errors import PolicyModelError
from nav_gym.policy.history import EpisodeMemory, GreedyActor

EXPORT_DIR = 'export'            # RUN/export
ONNX_FILE = 'policy.onnx'
META_FILE = 'policy.json'
INPUT_NAME = 'observation'
OUTPUT_NAME = 'q_values'
FORMAT = 1                       # policy.json's format; a reader refuses another
#: how the env turns a camera image into the observation (nav_gym.env.observation): the export
#: records it, and the node refuses an export made for another
OBSERVATION = {'shape': list(OBS_SHAPE), 'dtype': 'uint8', 'layout': 'CHW', 'colour': 'RGB',
               'resize': 'cv2.INTER_AREA', 'scaling': 'in the graph: x / 255'}
_KEYS = ('format', 'actions', 'control_period', 'camera_hfov_deg', 'observation', 'input',
         'output', 'run', 'checkpoint', 'learner', 'config')


@dataclass(frozen=True)
class ExportSpec:
    """An export directory's ``policy.json``, checked."""

    path: Path                                   # the export directory
    twists: tuple[tuple[float, float], ...]      # each action's (linear m/s, angular rad/s)
    control_period: float
    camera_hfov_deg: float
    meta: dict[str, Any]                         # the whole policy.json

    @property
    def onnx(self) -> Path:
        """Return the network's file."""
        return self.path / ONNX_FILE

    @property
    def config(self) -> dict[str, Any]:
        """Return the run's settings (TrainConfig's fields) the policy was trained with."""
        return dict(self.meta['config'])


def is_export(path: str | Path) -> bool:
    """Tell whether ``path`` is meant as an export directory (it holds policy.json or .onnx)."""
    path = Path(path).expanduser()
    return path.is_dir() and ((path / META_FILE).exists() or (path / ONNX_FILE).exists())


def read_export(path: str | Path) -> ExportSpec:
    """Return the export at ``path``; raise PolicyModelError saying in one line what is wrong."""
    path = Path(path).expanduser()
    where = f'export {path}'
    for name in (ONNX_FILE, META_FILE):
        if not (path / name).is_file():
            raise PolicyModelError(f'{where} has no {name}: export the run again with '
                                   '`nav-gym-export RUN`')
    try:
        meta = json.loads((path / META_FILE).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PolicyModelError(f'{where}: cannot read {META_FILE} ({exc})') from None
    if not isinstance(meta, dict) or meta.get('format') != FORMAT:
        raise PolicyModelError(f'{where}: {META_FILE} is not a format-{FORMAT} visnav export')
    missing = [key for key in _KEYS if key not in meta]
    if missing:
        raise PolicyModelError(f'{where}: {META_FILE} lacks {", ".join(missing)}')
    if meta['observation'] != OBSERVATION:
        raise PolicyModelError(f'{where} was made for the observation {meta["observation"]}, '
                               f'this node makes {OBSERVATION}')
    try:
        twists = tuple((float(linear), float(angular)) for linear, angular in meta['actions'])
        period, hfov = float(meta['control_period']), float(meta['camera_hfov_deg'])
    except (TypeError, ValueError) as exc:
        raise PolicyModelError(f'{where}: {META_FILE} has a bad actions, control_period or '
                               f'camera_hfov_deg ({exc})') from None
    if len(twists) != len(ACTION_NAMES) or not period > 0 or not 0 < hfov < 180:
        raise PolicyModelError(f'{where}: {META_FILE} needs {len(ACTION_NAMES)} actions, a '
                               'control_period > 0 and a camera_hfov_deg in (0, 180)')
    if not isinstance(meta['config'], dict):
        raise PolicyModelError(f'{where}: {META_FILE} config must be a mapping')
    return ExportSpec(path, twists, period, hfov, meta)


class OnnxActor(GreedyActor):
    """The exported Q-network on ONNX Runtime: argmax Q, and the Q-values (as DQNActor)."""

    name = 'dqn'

    def __init__(self, spec: ExportSpec, threads: int = 1) -> None:
        """Open ``spec``'s network on the CPU with ``threads`` intra-op threads."""
        try:
            import onnxruntime as ort
        except ImportError as exc:
            raise PolicyModelError(f'an export needs onnxruntime ({exc}): pip install '
                                   'onnxruntime') from None
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        options.log_severity_level = 3  # errors only: the node's log is for the node
        try:
            self.session = ort.InferenceSession(str(spec.onnx), options,
                                                providers=['CPUExecutionProvider'])
        except Exception as exc:  # onnxruntime raises its own kinds for a bad file
            raise PolicyModelError(f'cannot read the network {spec.onnx} ({type(exc).__name__}:'
                                   f' {str(exc).splitlines()[0] if str(exc) else ""})') from None
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if ([i.name for i in inputs] != [INPUT_NAME] or inputs[0].type != 'tensor(uint8)'
                or [o.name for o in outputs] != [OUTPUT_NAME]):
            raise PolicyModelError(
                f'{spec.onnx} must take one uint8 input {INPUT_NAME!r} and give one output '
                f'{OUTPUT_NAME!r}; it takes {[(i.name, i.type) for i in inputs]} and gives '
                f'{[o.name for o in outputs]}')
        self.spec = spec
        # a learner with memory takes its last frames (and action): kept as the torch actor does
        n_actions = len(spec.twists) if spec.meta['learner'].get('previous_action') else 0
        try:
            self.memory = EpisodeMemory.of(int(inputs[0].shape[1]), OBS_SHAPE[0], n_actions)
        except (TypeError, ValueError) as exc:
            raise PolicyModelError(f'{spec.onnx}: its input {inputs[0].shape} does not fit '
                                   f'{META_FILE} ({exc})') from None

    def q_values(self, network_input: np.ndarray) -> np.ndarray:
        """Return the Q-values of the network's input (a frame, or a memory's stack)."""
        batch = np.ascontiguousarray(network_input, dtype=np.uint8)[None]
        return self.session.run([OUTPUT_NAME], {INPUT_NAME: batch})[0][0]
