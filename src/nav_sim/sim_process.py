"""Start and stop a ``sim_node`` child process (what ``ros2 run nav_sim sim_node`` does)."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from typing import Any

from nav_sim.config import NodeConfig, SimConfig
from nav_sim.errors import ConfigError
from nav_sim.paths import package_prefix

_PARAM_TYPES = {f.name: type(f.default) for c in (SimConfig, NodeConfig)
                for f in dataclasses.fields(c)}


def typed_params(params: Mapping[str, Any]) -> dict[str, Any]:
    """Convert values to the declared type of each sim_node parameter (a YAML ``90`` for a
    double parameter must reach the node as ``90.0``); unknown names raise ConfigError."""
    unknown = sorted(set(params) - set(_PARAM_TYPES))
    if unknown:
        raise ConfigError(f'unknown sim_node parameter(s) {unknown}; known: '
                          f'{sorted(_PARAM_TYPES)}')
    out = {}
    for key, value in params.items():
        kind = _PARAM_TYPES[key]
        try:
            if kind is bool and isinstance(value, str):
                if value.lower() not in ('true', 'false'):
                    raise ValueError(value)
                out[key] = value.lower() == 'true'
            else:
                out[key] = kind(value)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f'sim_node parameter {key}: cannot convert {value!r} to '
                              f'{kind.__name__}') from exc
        if kind is int and isinstance(value, float) and not value.is_integer():
            raise ConfigError(f'sim_node parameter {key} must be an integer, got {value!r}')
    return out


def executable_command() -> list[str]:
    """``<prefix>/lib/nav_sim/sim_node`` if installed (as ros2run finds it), else ``-m``."""
    prefix = package_prefix('nav_sim')
    if prefix is not None:
        path = prefix / 'lib' / 'nav_sim' / 'sim_node'
        if os.access(path, os.X_OK):
            return [str(path)]
    return [sys.executable, '-m', 'nav_sim.sim_node']


def ros_args(namespace: str = '', params: Mapping[str, Any] | None = None,
             params_file: str | None = None) -> list[str]:
    """``--ros-args`` for a namespace, a params file and single parameters."""
    args = ['--ros-args']
    if namespace:
        args += ['-r', f'__ns:={namespace}']
    if params_file:
        args += ['--params-file', params_file]
    for key, value in typed_params(params or {}).items():
        if isinstance(value, bool):
            text = str(value).lower()
        elif isinstance(value, float):
            text = repr(value)  # always has a '.' or an exponent: parsed as a double
        else:
            text = str(value)
        args += ['-p', f'{key}:={text}']
    return args


def _stop_with_parent() -> None:
    """In the child, before exec: SIGTERM when the parent dies (even by SIGKILL), so a lockstep
    sim never outlives the env that started it (Linux prctl PR_SET_PDEATHSIG)."""
    if sys.platform.startswith('linux'):
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG = 1


class SimProcess:
    """A sim_node child process; ``stop()`` sends SIGINT and always reaps it."""

    def __init__(self, namespace: str = '', params: Mapping[str, Any] | None = None,
                 params_file: str | None = None, quiet: bool = True,
                 env: Mapping[str, str] | None = None) -> None:
        command = executable_command() + ros_args(namespace, params, params_file)
        # quiet: keep stderr (the node's log) in a temporary file to explain a failed start
        self._log = tempfile.TemporaryFile() if quiet else None
        self.process = subprocess.Popen(command, stdout=subprocess.DEVNULL if quiet else None,
                                        stderr=self._log,
                                        env=dict(env) if env is not None else None,
                                        preexec_fn=_stop_with_parent)
        self.namespace = namespace

    def failure(self) -> str | None:
        """None while the process runs; else its exit code and the end of its log."""
        code = self.process.poll()
        if code is None:
            return None
        tail = ''
        if self._log is not None:
            self._log.seek(0)
            lines = self._log.read().decode(errors='replace').strip().splitlines()
            tail = ': ' + ' | '.join(lines[-5:]) if lines else ''
        return f'sim_node exited with code {code}{tail}'

    def alive(self) -> bool:
        return self.process.poll() is None

    def stop(self, timeout: float = 10.0) -> int:
        """Interrupt (as Ctrl-C does), wait, kill if needed; returns the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self._log is not None:
            self._log.close()
            self._log = None
        return self.process.returncode

    def __enter__(self) -> SimProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
