"""The machine-wide lock directory that every runner, user and container shares."""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Mapping
from pathlib import Path

LOCK_DIR_ENV = "ROS_ISOLATED_TEST_LOCK_DIR"
DEFAULT_DIR_NAME = "ros-isolated-test-domains"
#: Like /tmp: everyone may create lock files, nobody may delete another user's.
SHARED_DIR_MODE = 0o1777


class LockDirError(RuntimeError):
    """The lock directory cannot be used; the message names the path and the fix."""


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
