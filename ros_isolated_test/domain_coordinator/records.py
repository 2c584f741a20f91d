"""The holder record: who holds a domain ID, left beside its lock for ``status``.

Records live in a directory every user may write to, so a record read back is
untrusted: it is kept only when its PID and time are in range, and its text fields
are made display-safe (no control character can forge a line or drive a terminal).
The same checks read the records of the queue's tickets and of resource holds; a
record's time and user are shown through :func:`iso_time` and :func:`user_name`.
"""

from __future__ import annotations

import contextlib
import os
import pwd
import stat
import time
from collections.abc import Sequence
from pathlib import Path

from ros_isolated_test.atomic_file import write_atomically
from ros_isolated_test.domain_coordinator.lock_dir import owned_file, read_small_file
from ros_isolated_test.process import proc
from ros_isolated_test.text import DISPLAY_LIMIT, display_text, json_string, shell_join

#: Latest time a record may carry: the end of year 9999, which every strftime can show.
LATEST_TIME = 253402300799.0
#: Longest text shown for a record's command (user and host: :data:`SHORT_TEXT`).
LONG_TEXT = DISPLAY_LIMIT
SHORT_TEXT = 256


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
        """Local start time, to the second ("-" when unknown)."""
        return iso_time(self.started)

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


def iso_time(when: float) -> str:
    """Local time to the second, or "-" for a time no record of a real runner carries."""
    if not 0.0 < when <= LATEST_TIME:  # also NaN
        return "-"
    try:
        return time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(when))
    except (OverflowError, OSError, ValueError):
        return "-"


def record_pid(value: object, limit: int) -> int | None:
    """A record's PID when it could be a real one (an int from 1 to below ``limit``).

    ``limit`` is :func:`proc.pid_max`, read once by the caller for all its records.
    """
    if type(value) is not int:  # not a bool, not a float such as 1e400
        return None
    return value if 0 < value < limit else None


def record_time(value: object) -> float | None:
    """A record's time when it is one a real runner writes (finite, from 1970 to 9999)."""
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return None
    # Compared before any conversion: float() of a 400-digit int raises OverflowError.
    return float(value) if 0 < value <= LATEST_TIME else None


def record_text(value: object, limit: int = SHORT_TEXT) -> str | None:
    """A record's text field, display-safe, or None when it is no string."""
    return display_text(value, limit) if isinstance(value, str) else None


def parse_record(text: str) -> dict[str, object] | None:
    """A record file's JSON object, or None for anything else a planted file may hold."""
    import json

    try:
        data = json.loads(text)
    except (ValueError, RecursionError):  # bad JSON, digits beyond int limits, deep nesting
        return None
    return data if isinstance(data, dict) else None


def user_name(uid: int | None) -> str:
    """The name of user ``uid``, display-safe: the one lookup records and ``status`` use.

    The numeric UID where the passwd database lacks it (containers), "?" for None (a
    process gone before its owner was read).
    """
    if uid is None:
        return "?"
    try:
        return display_text(pwd.getpwuid(uid).pw_name, SHORT_TEXT)
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
        user=user_name(os.getuid()),
        command=shell_join(command),
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


def mark_held(lock_dir: Path, domain_id: int) -> Path | None:
    """The user's record for the ID as an empty file, when a full one cannot be written.

    On a full disk a file with no data still fits: its name and time alone tell the
    next holder that this one took the ID (``escaped``). When another user planted a
    file at the record's path, a record of a name of our own (never guessed) takes its
    place. None when nothing can be written.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    own = f"domain-{domain_id}.uid{os.getuid()}.{os.getpid()}-{os.urandom(4).hex()}.holder.json"
    for path, extra in ((record_path(lock_dir, domain_id), 0), (lock_dir / own, os.O_EXCL)):
        try:
            fd = os.open(path, flags | extra, 0o644)
        except OSError:
            continue
        try:
            info = os.fstat(fd)
            if stat.S_ISREG(info.st_mode) and info.st_uid == os.getuid():
                os.utime(fd)
                return path
        except OSError:
            pass
        finally:
            os.close(fd)
    return None


def refresh(path: Path) -> bool:
    """Touch our record, so it is newer than any release: False when it is gone or not ours."""
    if not owned_file(path):
        return False
    try:
        os.utime(path, follow_symlinks=False)
    except OSError:
        return False
    return True


def read_records(lock_dir: Path, domain_id: int) -> list[Holder]:
    """Every valid record for the ID, newest first, display-safe; the others are skipped.

    Valid: a JSON object of this ID, with a PID below pid_max, a time from 1970 to 9999
    and text fields, as :func:`write_record` writes it. Anything else was planted.
    """
    holders: list[Holder] = []
    limit = proc.pid_max()
    for path in lock_dir.glob(f"domain-{domain_id}.uid*.holder.json"):
        try:
            data = parse_record(read_small_file(path))
        except (OSError, ValueError):  # unreadable, not a regular file, not UTF-8
            continue
        if data is None or type(data.get("domain_id")) is not int:
            continue
        if data["domain_id"] != domain_id:
            continue
        pid = record_pid(data.get("pid"), limit)
        started = record_time(data.get("started"))
        user = record_text(data.get("user"))
        command = record_text(data.get("command"), LONG_TEXT)
        host = record_text(data.get("host", ""))
        if pid is None or started is None or user is None or command is None or host is None:
            continue
        holders.append(Holder(domain_id, pid, user, command, started, host))
    holders.sort(key=lambda holder: holder.started, reverse=True)
    return holders


def remove_record(path: Path) -> None:
    """Best effort: a stale record is harmless, ``status`` only trusts held locks."""
    if owned_file(path):
        with contextlib.suppress(OSError):
            path.unlink()
