"""Start and stop a ``sim_node`` child process (what ``ros2 run nav_sim sim_node`` does)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Mapping
from typing import Any

from nav_sim.paths import package_prefix


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
    for key, value in (params or {}).items():
        text = str(value).lower() if isinstance(value, bool) else str(value)
        args += ['-p', f'{key}:={text}']
    return args


class SimProcess:
    """A sim_node child process; ``stop()`` sends SIGINT and always reaps it."""

    def __init__(self, namespace: str = '', params: Mapping[str, Any] | None = None,
                 params_file: str | None = None, quiet: bool = True,
                 env: Mapping[str, str] | None = None) -> None:
        command = executable_command() + ros_args(namespace, params, params_file)
        out = subprocess.DEVNULL if quiet else None
        self.process = subprocess.Popen(command, stdout=out, stderr=out,
                                        env=dict(env) if env is not None else None)
        self.namespace = namespace

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
        return self.process.returncode

    def __enter__(self) -> SimProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
