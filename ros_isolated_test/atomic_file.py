"""Replacing a small file whole: a reader, or a kill, never sees half of it.

Shared by the result file and the coordinator's holder records. No ``tempfile``:
its import (``random``, ``shutil``, ...) costs more than every write a run makes.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from pathlib import Path

from ros_isolated_test import libc

TYPE_CHECKING = False

_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
#: The null device's number on Linux (1:3), wherever its node lies (a container's /dev).
_NULL_DEVICE = os.makedev(1, 3)
_KINDS = (
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISSOCK, "a socket"),
)
#: The fix for a path a rename must not replace, as the one-line errors give it.
SPECIAL_FIX = "name a regular file instead, or /dev/null to discard the result"


class NotReplaceableError(OSError):
    """``path`` is a device node, FIFO or socket (or a symlink to one): a rename would replace it.

    As root, ``--junit-xml /dev/null`` once replaced the machine's /dev/null.
    """

    def __init__(self, path: Path, kind: str) -> None:
        super().__init__(errno.EEXIST, f"it is {kind}, which is never replaced", str(path))


def discards(path: Path) -> bool:
    """Whether ``path`` is the null device (or a symlink to it): what is written there is lost.

    Compared by device number, so a node made with ``mknod c 1 3`` counts too.
    """
    try:
        found = os.stat(path)
    except (OSError, ValueError):
        return False
    return stat.S_ISCHR(found.st_mode) and found.st_rdev == _NULL_DEVICE


def special_kind(path: Path) -> str | None:
    """What ``path`` is when a rename must never replace it (``a FIFO``, ``a symlink to ...``).

    None for nothing there, a regular file, a directory, or a symlink to one of those (or
    to nothing): the symlink itself is replaced, never what it points to.
    """
    try:
        found = os.lstat(path)
    except (OSError, ValueError):
        return None
    link = stat.S_ISLNK(found.st_mode)
    if link:
        try:
            found = os.stat(path)
        except (OSError, ValueError):
            return None
    for test, kind in _KINDS:
        if test(found.st_mode):
            return f"a symlink to {kind}" if link else kind
    return None


def _check(path: Path, replacing: os.stat_result | None) -> None:
    """Refuse to replace a special file, unless it is ``replacing`` (the same node)."""
    kind = special_kind(path)
    if kind is None:
        return
    if replacing is not None:
        with contextlib.suppress(OSError):
            now = os.lstat(path)
            if (now.st_dev, now.st_ino) == (replacing.st_dev, replacing.st_ino):
                return
    raise NotReplaceableError(path, kind)


def write_atomically(
    path: Path, data: bytes, mode: int = 0o644, replacing: os.stat_result | None = None
) -> None:
    """Write ``data`` beside ``path`` under a name of this process's own, then rename it in.

    The folder is created if missing. ``mode`` is set explicitly, whatever the umask.
    A device node, FIFO or socket at ``path`` (or a symlink to one) is never replaced:
    :class:`NotReplaceableError`, checked before the temporary file is made, and decided
    again by what the rename itself took away (:func:`_rename_in`), so one that appeared
    at any instant before is kept too. ``replacing``: the one such node (its ``lstat``)
    that may go, the test's own, kept elsewhere.
    """
    _check(path, replacing)
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
        _rename_in(temp, path, replacing)
    except BaseException as error:
        if not isinstance(error, _LeftAtTemporary):
            with contextlib.suppress(OSError):
                os.unlink(temp)
        raise


# --- the rename: never over a special file, not even one that appeared after every check ----

_AT_FDCWD = -100
_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2
#: renameat2's answers where the kernel or the file system cannot do a flag (NFS, old
#: kernels): then a check just before a plain rename, a window of microseconds.
_UNSUPPORTED = (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP)


class _LeftAtTemporary(OSError):
    """A special file swapped out could not be put back: it is at the temporary name."""


def _rename_in(temp: Path, path: Path, replacing: os.stat_result | None) -> None:
    """Put ``temp`` at ``path``, deciding by what is really there as the rename happens.

    renameat2(2): ``RENAME_EXCHANGE`` swaps the two names in one step, so what was at
    ``path`` is then at ``temp``, untouched; a special file (or a directory) is swapped
    back at once, anything else is unlinked, as a rename would have dropped it. Nothing at
    ``path``: ``RENAME_NOREPLACE``, which fails if something appeared meanwhile (then
    looked at again). Where renameat2 cannot (an old C library or kernel, a file system
    without these flags): a check just before a plain rename.
    """
    call = libc.renameat2()
    source, target = os.fsencode(temp), os.fsencode(path)
    for _attempt in range(100):
        if call is None:
            break
        if call(_AT_FDCWD, source, _AT_FDCWD, target, _RENAME_EXCHANGE) == 0:
            _drop_or_put_back(temp, path, replacing, call)
            return
        number = libc.errno()
        if number == errno.ENOENT:
            if call(_AT_FDCWD, source, _AT_FDCWD, target, _RENAME_NOREPLACE) == 0:
                return
            number = libc.errno()
            if number == errno.EEXIST:
                continue  # something appeared at the path: swap and look at it
        if number in _UNSUPPORTED:
            break
        raise OSError(number, os.strerror(number), str(path))
    else:
        raise FileExistsError(errno.EEXIST, "the path keeps changing", str(path))
    _check(path, replacing)
    os.replace(temp, path)


def _drop_or_put_back(
    temp: Path, path: Path, replacing: os.stat_result | None, call: libc.Renameat2
) -> None:
    """``temp`` holds what was at ``path``: unlink it, or swap a special file back."""
    old = os.lstat(temp)
    kind = "a directory" if stat.S_ISDIR(old.st_mode) else special_kind(temp)
    mine = replacing is not None and (old.st_dev, old.st_ino) == (
        replacing.st_dev,
        replacing.st_ino,
    )
    if kind is None or (mine and kind != "a directory"):
        os.unlink(temp)
        return
    if call(_AT_FDCWD, os.fsencode(temp), _AT_FDCWD, os.fsencode(path), _RENAME_EXCHANGE):
        number = libc.errno()
        raise _LeftAtTemporary(
            number, f"{kind} was at the path and could not be put back from {temp}", str(path)
        )
    if kind == "a directory":
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
    raise NotReplaceableError(path, kind)
