"""Replacing a small file whole: a reader, or a kill, never sees half of it.

Shared by the result file and the coordinator's holder records. No ``tempfile``:
its import (``random``, ``shutil``, ...) costs more than every write a run makes.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC


def write_atomically(path: Path, data: bytes, mode: int = 0o644) -> None:
    """Write ``data`` beside ``path`` under a name of this process's own, then rename it in.

    The folder is created if missing. ``mode`` is set explicitly, whatever the umask.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    for _attempt in range(100):
        # Unpredictable: in the shared lock directory, other users could plant the name.
        temp = path.with_name(f".{path.name}.{os.getpid()}.{os.urandom(4).hex()}.tmp")
        try:
            fd = os.open(temp, _FLAGS, mode)
        except FileExistsError:
            continue
        break
    else:
        raise FileExistsError(f"no free temporary name beside {path}")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            os.fchmod(handle.fileno(), mode)
        os.replace(temp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise
