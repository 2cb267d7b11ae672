"""Atomic file writes of a run: a temporary file, fsync, rename; hard links."""

from __future__ import annotations

import errno
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from nav_gym.errors import DiskFullError


def atomic_write(path: Path, write: Callable[[Any], Any], size_hint: int | None = None) -> None:
    """Write through ``write(fileobj)`` to a temporary file, fsync, then rename over ``path``.

    The temporary file is removed on any error, Ctrl-C included.  A full disk raises
    DiskFullError naming the file and ``size_hint`` (bytes the file needs, if known).
    """
    tmp = path.with_name(f'.{path.name}.tmp')
    try:
        with open(tmp, 'wb') as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
            need = f'about {_size(size_hint)}' if size_hint else 'more space'
            raise DiskFullError(f'no space left on the device while writing {path}: it needs '
                                f'{need}; free some space') from None
        raise


def _size(nbytes: float) -> str:
    for unit in ('bytes', 'kB', 'MB', 'GB'):
        if nbytes < 1000 or unit == 'GB':
            return f'{nbytes:.0f} {unit}' if unit == 'bytes' else f'{nbytes:.1f} {unit}'
        nbytes /= 1000
    return ''


def write_text(path: Path, text: str) -> None:
    """Write a small text file atomically."""
    atomic_write(path, lambda handle: handle.write(text.encode()))


def link(source: Path, path: Path) -> bool:
    """Make ``path`` a hard link of ``source`` atomically; False where links are refused."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f'.{path.name}.tmp')
    try:
        tmp.unlink(missing_ok=True)
        os.link(source, tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            return False
        raise
    return True
