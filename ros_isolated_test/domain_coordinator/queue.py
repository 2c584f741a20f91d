"""First come, first served among runners waiting for a domain ID.

Each waiter holds a flock on a ticket file named after its arrival time; a runner
may take an ID only when no live ticket is older than its own. A waiter that dies
leaves its ticket unlocked, and the next runner to look removes or ignores it.

A ticket holds a small record of its waiter (PID, command, since when) for ``status``.
The directory is shared and hostile: the record is written into a file we just created
(never through a link), read back only from regular files, size-bounded, and the user
shown is the file's owner, which nobody can fake.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import stat
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

from ros_isolated_test.domain_coordinator.flock import try_lock, wait_lock
from ros_isolated_test.domain_coordinator.holder import (
    json_string,
    owned_file,
    read_small_file,
)
from ros_isolated_test.domain_coordinator.lock_dir import LockDirError, ensure_lock_dir

QUEUE_DIR = "queue"


class Ticket:
    """A runner's place in the queue, held until it gets an ID or gives up."""

    def __init__(self, queue: Queue, name: str, fd: int) -> None:
        self.queue = queue
        self.name = name
        self.fd = fd

    def ahead(self) -> int:
        """Live tickets older than this one."""
        return sum(1 for name in self.queue.live_tickets() if name < self.name)


class Waiter:
    """A runner waiting for an ID, as its ticket describes it."""

    __slots__ = ("command", "host", "pid", "position", "since", "user")

    def __init__(
        self, position: int, pid: int, user: str, command: str, since: float, host: str
    ) -> None:
        #: 1 for the head of the queue, the next to get an ID.
        self.position = position
        self.pid = pid
        self.user = user
        self.command = command
        self.since = since
        self.host = host

    @property
    def since_iso(self) -> str:
        """Local time the runner started waiting, to the second."""
        return time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(self.since))

    def as_dict(self) -> dict[str, object]:
        """The fields ``status --json`` shows."""
        return {
            "position": self.position,
            "pid": self.pid,
            "user": self.user,
            "command": self.command,
            "started": self.since,
            "host": self.host,
        }


def _record(command: Sequence[str] | None) -> bytes:
    """The ticket record of this waiter, as JSON (no ``json`` import: a runner writes it)."""
    from ros_isolated_test.domain_coordinator.holder import current_user

    words = list(command) if command is not None else list(sys.argv)
    fields = (
        f'"pid": {os.getpid()}',
        f'"user": {json_string(current_user())}',
        f'"command": {json_string(shlex.join(words))}',
        f'"started": {time.time()!r}',
        f'"host": {json_string(os.uname().nodename)}',
    )
    return ("{" + ", ".join(fields) + "}").encode("utf-8")


def _user_of(uid: int) -> str:
    import pwd

    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return str(uid)


class Queue:
    """The waiting runners of one lock directory."""

    def __init__(self, lock_dir: Path) -> None:
        self.path = lock_dir / QUEUE_DIR

    def usable(self) -> bool:
        """Whether the queue folder is a real folder (never followed through a link)."""
        try:
            return stat.S_ISDIR(os.lstat(self.path).st_mode)
        except OSError:
            return False

    def live_tickets(self) -> list[str]:
        """Names of the tickets whose waiter is alive; our own dead ones are removed."""
        live: list[str] = []
        if not self.usable():
            return live
        with contextlib.suppress(OSError):
            for entry in os.scandir(self.path):
                if not entry.name.endswith(".ticket"):
                    continue
                if self._held(Path(entry.path)):
                    live.append(entry.name)
                elif owned_file(Path(entry.path)):
                    with contextlib.suppress(OSError):
                        os.unlink(entry.path)
        return sorted(live)

    def waiters(self) -> list[Waiter]:
        """Every live waiter, first in line first.

        A ticket without a readable record still counts: its name holds the PID and
        the arrival time.
        """
        import json

        found: list[Waiter] = []
        for position, name in enumerate(self.live_tickets(), start=1):
            path = self.path / name
            arrived, _dash, pid_text = name[: -len(".ticket")].partition("-")
            pid = int(pid_text) if pid_text.isdigit() else 0
            since = int(arrived) / 1e9 if arrived.isdigit() else 0.0
            command, host = "(no record)", ""
            try:
                owner = _user_of(os.lstat(path).st_uid)
            except OSError:
                continue  # gone meanwhile: it got its ID
            with contextlib.suppress(OSError, ValueError, TypeError, AttributeError):
                data = json.loads(read_small_file(path))
                command = str(data["command"])
                host = str(data.get("host", ""))
                pid = int(data["pid"])
                since = float(data["started"])
            found.append(Waiter(position, pid, owner, command, since, host))
        return found

    def waiting(self) -> bool:
        """Whether anyone waits: then a newcomer queues too, instead of jumping ahead."""
        return bool(self.live_tickets())

    @staticmethod
    def _held(path: Path) -> bool:
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
        except OSError:
            return False
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                return False
            # Taking the lock means nobody holds it: its waiter is gone.
            return not try_lock(fd)
        except OSError:
            return False
        finally:
            os.close(fd)

    @contextlib.contextmanager
    def ticket(self, command: Sequence[str] | None = None) -> Iterator[Ticket | None]:
        """Take a place at the end of the queue for the ``with`` block.

        ``command`` is recorded in the ticket for ``status`` (default: this process's
        own command line). Yields None when the queue folder is unusable (something
        planted there): the runner then still waits, only without the
        first-come-first-served order.
        """
        fd: int | None = None
        staging: Path | None = None
        try:
            ensure_lock_dir(self.path)
            name = f"{time.time_ns():020d}-{os.getpid()}.ticket"
            path = self.path / name
            # Locked under a name nobody looks at, then renamed into the queue: an
            # unlocked ticket would look dead and could be removed by another runner.
            staging = self.path / f".{name}.new"
            fd = os.open(
                staging, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644
            )
            with contextlib.suppress(OSError):
                os.fchmod(fd, 0o644)  # others must open it to see that it is held
            with contextlib.suppress(OSError):
                # Our own new file (O_EXCL): written before it appears in the queue. A
                # full disk only costs status the record, never the place in line.
                os.write(fd, _record(command))
            wait_lock(fd)
            os.rename(staging, path)
        except (OSError, LockDirError):
            if fd is not None:
                os.close(fd)
            if staging is not None:
                with contextlib.suppress(OSError):
                    os.unlink(staging)
            yield None
            return
        try:
            yield Ticket(self, name, fd)
        finally:
            with contextlib.suppress(OSError):
                os.unlink(path)
            os.close(fd)
