"""Who holds a domain ID: the record a holder leaves beside its lock for ``status``."""

from __future__ import annotations

import contextlib
import json
import os
import pwd
import shlex
import socket
import stat
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path


@dataclass(frozen=True)
class Holder:
    """A runner holding an ID: enough for a person to find and judge it."""

    domain_id: int
    pid: int
    user: str
    command: str
    started: float
    host: str

    @property
    def started_iso(self) -> str:
        """Local start time, to the second."""
        return time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(self.started))


def current_user() -> str:
    """The user name, or the numeric UID where the passwd database lacks it (containers)."""
    uid = os.getuid()
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return str(uid)


def record_path(lock_dir: Path, domain_id: int, uid: int | None = None) -> Path:
    """One record per ID and user: a user never writes a file another user owns."""
    uid = os.getuid() if uid is None else uid
    return lock_dir / f"domain-{domain_id}.uid{uid}.holder.json"


def write_record(lock_dir: Path, domain_id: int, command: Sequence[str]) -> Path:
    """Atomically replace this user's record for the ID (rename of a fresh temp file)."""
    holder = Holder(
        domain_id=domain_id,
        pid=os.getpid(),
        user=current_user(),
        command=shlex.join(command),
        started=time.time(),
        host=socket.gethostname(),
    )
    path = record_path(lock_dir, domain_id)
    if os.path.lexists(path) and not owned_file(path):
        # Planted by someone else: root could rename over it, but never writes what
        # it does not own. The reservation stands without a record.
        raise PermissionError(f"{path} belongs to someone else")
    fd, temp_name = tempfile.mkstemp(dir=lock_dir, prefix=".holder-", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            json.dump(asdict(holder), handle)
        os.chmod(temp_name, 0o644)
        os.replace(temp_name, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp_name)
        raise
    return path


def read_records(lock_dir: Path, domain_id: int) -> list[Holder]:
    """Every readable record for the ID, newest first; unreadable ones are skipped."""
    holders: list[Holder] = []
    for path in lock_dir.glob(f"domain-{domain_id}.uid*.holder.json"):
        try:
            data = json.loads(read_small_file(path))
            holders.append(
                Holder(
                    domain_id=int(data["domain_id"]),
                    pid=int(data["pid"]),
                    user=str(data["user"]),
                    command=str(data["command"]),
                    started=float(data["started"]),
                    host=str(data.get("host", "")),
                )
            )
        except (OSError, ValueError, KeyError, TypeError):
            continue
    holders.sort(key=lambda holder: holder.started, reverse=True)
    return holders


def remove_record(path: Path) -> None:
    """Best effort: a stale record is harmless, ``status`` only trusts held locks."""
    if owned_file(path):
        with contextlib.suppress(OSError):
            path.unlink()


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
