"""Who holds a domain ID: the record a holder leaves beside its lock for ``status``."""

from __future__ import annotations

import contextlib
import os
import pwd
import shlex
import stat
import time
from collections.abc import Sequence
from pathlib import Path

from ros_isolated_test.atomic_file import write_atomically

#: JSON string escapes: quote, backslash and every control character.
_JSON_ESCAPES = {ord('"'): '\\"', ord("\\"): "\\\\"} | {
    code: f"\\u{code:04x}" for code in range(0x20)
}


class Holder:
    """A runner holding an ID: enough for a person to find and judge it."""

    __slots__ = ("command", "domain_id", "host", "pid", "started", "user")

    def __init__(
        self, domain_id: int, pid: int, user: str, command: str, started: float, host: str
    ) -> None:
        self.domain_id = domain_id
        self.pid = pid
        self.user = user
        self.command = command
        self.started = started
        self.host = host

    @property
    def started_iso(self) -> str:
        """Local start time, to the second."""
        return time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(self.started))

    def as_dict(self) -> dict[str, object]:
        """The record's fields, as ``status --json`` and the record file carry them."""
        return {
            "domain_id": self.domain_id,
            "pid": self.pid,
            "user": self.user,
            "command": self.command,
            "started": self.started,
            "host": self.host,
        }

    def to_json(self) -> str:
        """The record as one JSON object, without importing ``json`` on a test's path."""
        fields = (
            f'"domain_id": {int(self.domain_id)}',
            f'"pid": {int(self.pid)}',
            f'"user": {json_string(self.user)}',
            f'"command": {json_string(self.command)}',
            f'"started": {float(self.started)!r}',
            f'"host": {json_string(self.host)}',
        )
        return "{" + ", ".join(fields) + "}"


def json_string(text: str) -> str:
    r"""``text`` as a JSON string literal; lone surrogates (undecodable bytes) as ``\uXXXX``."""
    escaped = text.translate(_JSON_ESCAPES)
    try:
        escaped.encode("utf-8")
    except UnicodeEncodeError:
        escaped = "".join(
            f"\\u{ord(char):04x}" if 0xD800 <= ord(char) <= 0xDFFF else char for char in escaped
        )
    return f'"{escaped}"'


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
        host=os.uname().nodename,
    )
    path = record_path(lock_dir, domain_id)
    if os.path.lexists(path) and not owned_file(path):
        # Planted by someone else: root could rename over it, but never writes what
        # it does not own. The reservation stands without a record.
        raise PermissionError(f"{path} belongs to someone else")
    write_atomically(path, holder.to_json().encode("utf-8"))
    return path


def read_records(lock_dir: Path, domain_id: int) -> list[Holder]:
    """Every readable record for the ID, newest first; unreadable ones are skipped."""
    import json

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
