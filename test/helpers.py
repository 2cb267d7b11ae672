"""Plain functions the test modules share: the one wait, a free TCP port, Ctrl-C for a node.

Fixtures live in ``conftest.py``.  These live here because ``conftest`` is no importable name:
pytest imports every folder's conftest.py as a module named ``conftest``, so a test module
gets them with ``from helpers import wait_until`` (pytest puts ``test/`` on ``sys.path``).
"""

from __future__ import annotations

import signal
import socket
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import pytest

T = TypeVar('T')

#: the repository's root (this checkout): its config/ and docs/, as the tests read them
REPO = Path(__file__).resolve().parents[1]


def wait_until(predicate: Callable[[], T], timeout: float, what: str,
               interval: float = 0.02, details: Callable[[], object] | None = None) -> T:
    """Poll ``predicate`` until it returns something truthy, and return that value.

    Once ``timeout`` seconds have passed without it, the test fails with
    ``'<what>: not within <timeout> s'`` (and ``details()``, if given: what is known only
    then, such as a child process's output).  The predicate may do work between checks (step
    a sim, read a file): it is called once more after the deadline before the test fails.
    Between calls it sleeps ``interval`` or the time left, whichever is shorter, never a
    negative time; ``interval=0`` polls back to back.
    """
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        left = deadline - time.monotonic()
        if left <= 0:
            more = f'\n{details()}' if details is not None else ''
            pytest.fail(f'{what}: not within {timeout} s{more}')
        time.sleep(min(interval, left))


def free_port() -> int:
    """Return a TCP port on 127.0.0.1 that nothing listens on (the OS picks one)."""
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def interrupt(process: subprocess.Popen, timeout: float = 15.0) -> tuple[int, str]:
    """Press Ctrl-C (SIGINT) on a child started with text pipes; its exit code and output.

    A child that has exited already is only reaped; one still running ``timeout`` seconds
    after the SIGINT is killed (and its exit code says so).  A child that writes to files
    instead of pipes gives an empty output.
    """
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
    return process.returncode, (out or '') + (err or '')


def reported_as_another_error() -> SystemError:
    """Return the error CPython raises when a C call returns a result with a Ctrl-C set.

    As ``_Py_CheckFunctionResult`` does: a SystemError with the interrupt as its cause (rclpy's
    ``take_response`` hit by a Ctrl-C, 2026-11-29).
    """
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError('<built-in method take_response of PyCapsule object> returned a '
                              'result with an exception set') from exc
    except SystemError as error:
        return error


def learner_env(spaces_only: type, learner):  # noqa: ANN001, ANN201
    """Return an env with only the spaces for ``learner``: in the agent's stacks with memory."""
    if not learner.memory:
        return spaces_only()
    from stable_baselines3.common.vec_env import DummyVecEnv

    from nav_gym.training.memory import agent_envs
    return agent_envs(DummyVecEnv([spaces_only]), learner)  # as training has it


def make_tiny_run(path, spaces_only: type, steps: int = 32, **settings: object):  # noqa: ANN201
    """Write a run directory at ``path`` with a tiny model of the default learner; return it.

    ``config.yaml`` holds ``TrainConfig(**settings)``; the model learns ``steps`` steps on an
    env with only the spaces (no sim; in the agent's stacks with memory) and
    is saved as ``checkpoints/dqn_<steps>_steps.zip``, then ``steps`` more as
    ``final_model.zip``: enough for evaluation, reports and the policy node, in seconds.
    """
    from nav_gym.training.config import TrainConfig
    from nav_gym.training.learner import learner_class, learner_kwargs, learner_policy
    config = TrainConfig(**settings)
    (path / 'config.yaml').write_text(config.to_yaml())
    learner = config.learner()
    model = learner_class(None, learner)(
        learner_policy(learner), learner_env(spaces_only, learner), buffer_size=64,
        learning_starts=16, batch_size=8, seed=3, device='cpu',
        **learner_kwargs(learner, config.gamma))
    (path / 'checkpoints').mkdir()
    model.learn(steps)
    model.save(path / 'checkpoints' / f'dqn_{steps}_steps.zip')
    model.learn(steps, reset_num_timesteps=False)
    model.save(path / 'final_model.zip')
    return path
