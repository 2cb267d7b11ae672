"""Start and stop node child processes: ``sim_node`` (what ``ros2 run nav_sim sim_node`` does)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from typing import Any

from nav_sim.core.config import convert
from nav_sim.errors import ConfigError
from nav_sim.interface import absolute_namespace
from nav_sim.paths import executable_path
from nav_sim.ros.settings import PARAMETER_TYPES, ros_integer_problem

READY_MESSAGE = 'nav_sim ready:'  # how the node's last start-up log line begins
ERROR_PREFIX = 'sim_node: '       # how the node's own one-line errors begin (then exit code 2)


def typed_params(params: Mapping[str, Any]) -> dict[str, Any]:
    """Convert values to the declared type of each sim_node parameter with :func:`convert`.

    A YAML ``90`` for a double parameter reaches the node as ``90.0``; ``3.7`` for an integer
    parameter, ``'yes'`` for a bool and unknown names raise ConfigError, as does an integer
    beyond the 64 bits a ROS parameter holds.
    """
    unknown = sorted(set(params) - set(PARAMETER_TYPES))
    if unknown:
        raise ConfigError(f'unknown sim_node parameter(s) {unknown}; known: '
                          f'{sorted(PARAMETER_TYPES)}')
    out = {}
    for key, value in params.items():
        try:
            out[key] = convert(key, PARAMETER_TYPES[key], value)
        except ConfigError as exc:
            raise ConfigError(f'sim_node parameter {exc}') from None
        problem = (ros_integer_problem(key, out[key])
                   if isinstance(out[key], int) and not isinstance(out[key], bool) else None)
        if problem:
            raise ConfigError(f'sim_node parameter {problem}')
    return out


def node_command(package: str, executable: str, module: str) -> list[str]:
    """``<prefix>/lib/PACKAGE/EXECUTABLE`` if installed (as ros2run finds it), else ``-m``."""
    path = executable_path(package, executable)
    if path is not None and os.access(path, os.X_OK):
        return [str(path)]
    return [sys.executable, '-m', module]


def executable_command() -> list[str]:
    """Return the sim node's command (``lib/nav_sim/sim_node`` if installed, else ``-m``)."""
    return node_command('nav_sim', 'sim_node', 'nav_sim.sim_node')


def ros_args(namespace: str = '', params: Mapping[str, Any] | None = None,
             params_file: str | None = None) -> list[str]:
    """``--ros-args`` for a namespace, a params file and single sim_node parameters."""
    return node_ros_args(namespace, typed_params(params or {}), params_file)


def node_ros_args(namespace: str = '', params: Mapping[str, Any] | None = None,
                  params_file: str | None = None) -> list[str]:
    """``--ros-args`` for any node: a namespace, a params file and typed single parameters.

    A float is always written with a '.' or an exponent, so ROS reads it as a double.
    """
    args = ['--ros-args']
    if namespace:
        args += ['-r', f'__ns:={absolute_namespace(namespace)}']
    if params_file:
        args += ['--params-file', params_file]
    for key, value in (params or {}).items():
        if isinstance(value, bool):
            text = str(value).lower()
        elif isinstance(value, float):
            text = repr(value)  # always has a '.' or an exponent: parsed as a double
        else:
            text = str(value)
        args += ['-p', f'{key}:={text}']
    return args


def child_preexec() -> None:
    """Start a child with a clean signal state and SIGTERM when its parent dies (before exec).

    A parent may block or ignore SIGINT (a Ray worker does both; a background job of a
    non-interactive shell ignores it), and both pass through exec: a sim that inherited the
    blocked SIGINT never saw the SIGINT that stops it, so every stop waited out its timeout and
    then killed it.  The child starts with the default SIGINT and SIGTERM and no blocked
    signal, as a command started from a terminal does.  And even if the parent is killed by
    SIGKILL, the child gets SIGTERM: a lockstep sim never outlives the env that started it
    (Linux prctl PR_SET_PDEATHSIG).
    """
    for number in (signal.SIGINT, signal.SIGTERM):  # after fork, this thread is the main one
        signal.signal(number, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_SETMASK, ())
    if sys.platform.startswith('linux'):
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, ctypes.c_ulong(signal.SIGTERM))  # PDEATHSIG


def exit_status(code: int) -> str:
    """Say how a process ended: 'exited with code 1', 'was killed by signal SIGKILL (9)'."""
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = 'an unknown signal'
        return f'was killed by signal {name} ({-code})'
    return f'exited with code {code}'


class NodeProcess:
    """A ROS node child process; ``stop()`` sends SIGINT and always reaps it."""

    def __init__(self, command: list[str], name: str, ready_message: str, quiet: bool = True,
                 env: Mapping[str, str] | None = None) -> None:
        """Start ``command``, a node called ``name`` that logs ``ready_message`` once started.

        ``quiet`` keeps the node's output in a temporary file (for ``failure`` and ``ready``).
        """
        self.name = name
        self.ready_message = ready_message
        self._log = tempfile.TemporaryFile() if quiet else None
        self.process = subprocess.Popen(command, stdout=self._log, stderr=self._log,
                                        env=dict(env) if env is not None else None,
                                        preexec_fn=child_preexec)
        self._ready = False

    def output(self) -> str:
        """Return what the node has printed so far ('' without ``quiet``)."""
        if self._log is None:
            return ''
        fd = self._log.fileno()  # pread: the child shares the offset, which must stay put
        return os.pread(fd, os.fstat(fd).st_size, 0).decode(errors='replace')

    def failure(self) -> str | None:
        """None while the process runs; else its exit code and why.

        Why: the node's own error lines (a bad parameter or world), else the end of its log.
        """
        code = self.process.poll()
        if code is None:
            return None
        lines = self.output().strip().splitlines()
        errors = [line.removeprefix(ERROR_PREFIX) for line in lines
                  if line.startswith(ERROR_PREFIX)]
        tail = ': ' + ' | '.join(errors or lines[-5:]) if lines else ''
        return f'{self.name} (pid {self.process.pid}) {exit_status(code)}{tail}'

    def ready(self) -> bool:
        """Tell whether the node has logged that it finished starting.

        Without ``quiet`` its log is not kept: then this only says that the process runs.
        """
        if self._log is None:
            return self.alive()
        if not self._ready and self.process.poll() is None:
            self._ready = self.ready_message in self.output()
        return self._ready

    def alive(self) -> bool:
        """Tell whether the process still runs."""
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

    def __enter__(self) -> NodeProcess:
        """Use as a context manager that stops the process."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop the process."""
        self.stop()


class SimProcess(NodeProcess):
    """A sim_node child process (what ``ros2 run nav_sim sim_node`` starts)."""

    def __init__(self, namespace: str = '', params: Mapping[str, Any] | None = None,
                 params_file: str | None = None, quiet: bool = True,
                 env: Mapping[str, str] | None = None) -> None:
        """Start sim_node in ``namespace`` with ``params`` and a ``params_file``."""
        super().__init__(executable_command() + ros_args(namespace, params, params_file),
                         'sim_node', READY_MESSAGE, quiet, env)
        self.namespace = namespace
