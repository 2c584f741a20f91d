"""The machine-wide lock directory that every runner, user and container shares.

Also the safe ways to open, read and own a file in it: anyone may plant anything there.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Mapping
from pathlib import Path

from ros_isolated_test import names, not_run

LOCK_DIR_ENV = names.LOCK_DIR
DEFAULT_DIR_NAME = "ros-isolated-test-domains"
#: Like /tmp: everyone may create lock files, nobody may delete another user's.
SHARED_DIR_MODE = 0o1777
#: Lock files are shared by all users: each must be able to open and flock them.
LOCK_FILE_MODE = 0o666
#: Errors creating a file that say the directory cannot take files at all: not one
#: file's problem, so no other file name would help.
_DIRECTORY_ERRORS = frozenset({errno.ENOSPC, errno.EROFS, errno.EDQUOT, errno.EACCES})


class LockDirError(not_run.NotRun, RuntimeError):
    """The lock directory cannot be used; the message names the path and the fix."""

    reason = not_run.BUSY  # as for no ID: the runners' shared place cannot be had


class UnusableLockFile(Exception):
    """Something other than a lock file we can open is at the path (planted by someone)."""


def lock_dir_from_env(environ: Mapping[str, str] | None = None) -> Path:
    """``ROS_ISOLATED_TEST_LOCK_DIR``, else a fixed folder under the system temp dir.

    The default is the same path for every user (not ``$TMPDIR``-relative per user), so
    all runners on a machine, and containers bind-mounting it, see one set of locks.
    """
    environ = os.environ if environ is None else environ
    configured = environ.get(LOCK_DIR_ENV, "").strip()
    if configured:
        return Path(configured)
    if os.path.isdir("/tmp"):
        return Path("/tmp", DEFAULT_DIR_NAME)
    import tempfile

    return Path(tempfile.gettempdir(), DEFAULT_DIR_NAME)


def _create_shared(path: Path) -> None:
    """Make the directory appear with mode 1777 at once: built aside, then renamed in.

    A directory created in place is briefly mode 0700 (mkdir's mode is cut by the
    umask), and another user's runner arriving then would find it unwritable.
    """
    import tempfile

    try:
        staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    except OSError as error:
        if error.errno == errno.EROFS:
            raise LockDirError(_read_only_message(path, "cannot create lock directory")) from None
        raise LockDirError(
            f"cannot create lock directory {path}: {error.strerror}; "
            f"create it (mode 1777) or point {LOCK_DIR_ENV} at a writable directory"
        ) from None
    try:
        os.chmod(staging, SHARED_DIR_MODE)
        os.rename(staging, path)
    except OSError:
        # Another runner created it first (or the rename failed): use what is there.
        with contextlib.suppress(OSError):
            os.rmdir(staging)


def _on_read_only_mount(path: Path) -> bool:
    """True when ``path`` sits on a mount that is read-only (for root too)."""
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _read_only_message(path: Path, what: str) -> str:
    """No mode can make a read-only mount writable: only another directory helps."""
    return (
        f"{what} {path}: it is on a read-only file system; point {LOCK_DIR_ENV} at a "
        "directory on a writable file system (shared by every runner that must not collide)"
    )


def ensure_lock_dir(path: Path) -> Path:
    """Create the directory shared (mode 1777) if missing; refuse anything that is not one."""
    if not os.path.lexists(path):
        _create_shared(path)
    try:
        info = os.lstat(path)
    except OSError as error:
        raise LockDirError(f"cannot read lock directory {path}: {error.strerror}") from None
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode):
        raise LockDirError(
            f"lock directory {path} is not a directory (a file or a symlink is there); "
            f"remove it or point {LOCK_DIR_ENV} at a directory"
        )
    if not os.access(path, os.W_OK | os.X_OK):
        if _on_read_only_mount(path):
            raise LockDirError(_read_only_message(path, "cannot use lock directory"))
        raise LockDirError(
            f"lock directory {path} is not writable by this user; "
            f"make it mode 1777 (chmod 1777 {path}) or point {LOCK_DIR_ENV} elsewhere"
        )
    return path


def open_lock_file(path: Path) -> int:
    """A read-only descriptor of a lock file, created openable by every user if missing.

    The one opener of the ID's lock files and of the resources' mutex. Read-only is
    enough for flock, so a lock file another user created can be used whatever its mode
    lets us write; one that exists is never changed, ours included. Never follows a
    symlink, never blocks on a FIFO. Raises :class:`UnusableLockFile` for anything
    planted at the path, :class:`LockDirError` when the directory can take no file.
    """
    flags = os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK
    try:
        # Created exclusively, else opened without O_CREAT: in a sticky directory,
        # fs.protected_regular refuses O_CREAT on another user's existing file.
        fd = os.open(path, flags | os.O_CREAT | os.O_EXCL, LOCK_FILE_MODE)
    except FileExistsError:
        try:
            fd = os.open(path, flags)
        except OSError as error:
            raise UnusableLockFile(f"{path}: {error.strerror}") from None
    except OSError as error:
        if error.errno in _DIRECTORY_ERRORS:
            raise LockDirError(
                f"cannot create lock file {path}: {error.strerror}; free space or grant "
                f"write access to {path.parent}, or point {LOCK_DIR_ENV} elsewhere"
            ) from None
        raise UnusableLockFile(f"{path}: {error.strerror}") from None
    else:
        # The umask cut the mode; every user must be able to open the file.
        with contextlib.suppress(OSError):
            os.fchmod(fd, LOCK_FILE_MODE)
    try:
        regular = stat.S_ISREG(os.fstat(fd).st_mode)
    except OSError:
        regular = False
    if not regular:
        os.close(fd)
        raise UnusableLockFile(f"{path} is not a regular file")
    return fd


def owned_file(path: Path) -> bool:
    """Whether ``path`` is a regular file of ours (not a link, not someone else's)."""
    try:
        info = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISREG(info.st_mode) and info.st_uid == os.getuid()


def read_small_file(path: Path, limit: int = 64 * 1024) -> str:
    """A small regular file's text; never follows a link, never blocks on a FIFO."""
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(f"{path} is not a regular file")
        return os.read(fd, limit).decode("utf-8")
    finally:
        os.close(fd)
