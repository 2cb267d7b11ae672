"""Export a trained policy for the robot: ``RUN/export/policy.onnx`` and ``policy.json``.

The acting Q-network (SB3's ``q_net``, the dueling one too) goes out whole: the uint8
observation in (a memory learner's stack of frames and action planes, which the exported
actor builds as the checkpoint's does), its scaling (``x / 255``, as SB3's
``preprocess_obs``), the CNN and the head, the Q-values out (an auxiliary depth head is not
part of it).  What the files hold is :mod:`nav_gym.policy.exported` (no torch), which also
reads them back.  Needs torch and the ``onnx`` package; the robot needs neither.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import warnings
from pathlib import Path
from typing import Any

from nav_gym.errors import PolicyModelError, TrainConfigError
from nav_gym.policy.actors import Acting, DQNActor, model_file, run_of
from nav_gym.policy.exported import (
    EXPORT_DIR,
    FORMAT,
    INPUT_NAME,
    META_FILE,
    OBSERVATION,
    ONNX_FILE,
    OUTPUT_NAME,
    ExportSpec,
    read_export,
)
from nav_gym.training.config import TrainConfig
from nav_gym.training.files import write_text
from nav_gym.training.run_dir import load_config

OPSET = 17  # ONNX Runtime 1.14 and later run it


def export_policy(model: str | Path, out: str | Path | None = None) -> ExportSpec:
    """Export ``model`` (a run directory or a checkpoint .zip) into ``out`` and return it.

    ``out`` defaults to ``RUN/export`` (beside the checkpoint when it lies in no run).  The
    files are written into a temporary directory first, so a failed export leaves no half.
    """
    checkpoint = model_file(model)
    run = run_of(checkpoint)
    try:
        config = load_config(run) if run is not None else TrainConfig()
    except TrainConfigError as exc:
        raise PolicyModelError(str(exc)) from None
    source = f'{run}/config.yaml' if run is not None else 'the training defaults'
    acting = Acting.of(config, source)
    target = Path(out).expanduser() if out else (run or checkpoint.parent) / EXPORT_DIR
    loaded = DQNActor.load(checkpoint, 'cpu')
    network = _acting_network(loaded, checkpoint)
    # the network's input: a frame, or a memory's stack (the actor keeps the history)
    shape = [1, *loaded.observation_space.shape]
    # the run's learner (its config names it); a checkpoint outside a run: what it saved
    learner = config.learner() if run is not None else getattr(loaded, 'learner', None)
    meta = {
        'format': FORMAT,
        'actions': [list(twist) for twist in acting.twists],
        'control_period': acting.control_period,
        'camera_hfov_deg': acting.hfov_deg,
        'observation': OBSERVATION,
        'input': {'name': INPUT_NAME, 'shape': shape, 'dtype': 'uint8'},
        'output': {'name': OUTPUT_NAME, 'shape': [1, len(acting.twists)], 'dtype': 'float32'},
        'run': str(run.resolve()) if run is not None else None,
        'checkpoint': str(checkpoint.resolve()),
        'learner': dataclasses.asdict(learner) if learner is not None else {'class': 'DQN'},
        'config': dataclasses.asdict(config),
        'opset': OPSET,
    }
    staging = target.with_name(f'.{target.name}.tmp')
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    try:
        _write_onnx(network, staging / ONNX_FILE, shape)
        write_text(staging / META_FILE, json.dumps(meta, indent=1) + '\n')
        spec = read_export(staging)  # what the node will check
        if target.exists():
            shutil.rmtree(target)
        staging.rename(target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return dataclasses.replace(spec, path=target)


def _acting_network(model: Any, checkpoint: Path) -> Any:
    """Return the network a policy acts with, or refuse a learner that cannot export."""
    network = getattr(model, 'q_net', None)
    if network is None:
        raise PolicyModelError(f'{checkpoint} is a {type(model).__name__}, not a DQN: only '
                               'the Q-network of a DQN learner exports')
    return network.eval()


def _write_onnx(network: Any, path: Path, shape: list[int]) -> None:
    """Trace ``network`` on a uint8 input of ``shape`` into an ONNX file at ``path``."""
    import torch
    example = torch.zeros(shape, dtype=torch.uint8)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter('ignore')  # the TorchScript exporter's deprecation notice
        torch.onnx.export(network, (example,), str(path), input_names=[INPUT_NAME],
                          output_names=[OUTPUT_NAME], opset_version=OPSET, dynamo=False)
