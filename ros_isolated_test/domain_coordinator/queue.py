"""First come, first served among runners waiting for a domain ID.

Each waiter holds a flock on a ticket file named after its arrival time; a runner
may take an ID only when no live ticket is older than its own. A waiter that dies
leaves its ticket unlocked, and the next runner to look removes or ignores it.

A ticket holds a small record of its waiter (PID, command, since when) for ``status``.
The directory is shared and hostile: the record is written into a file we just created
(never through a link), read back only from regular files, size-bounded, and the user
shown is the file's owner, which nobody can fake.

The shared queue folder can be planted too (a file, a symlink, another user's folder
others may not write or may empty): a runner then queues in a folder of its own user
(``queue.uid<UID>``), as it falls back to a lock file of its own, and says so. Every
runner reads every such folder, so arrival order holds across all of them.

The same folders, under another name, hold what runners hold of machine resources
(``resource_holds``): a hold is a ticket kept for the test's whole life.
"""

from __future__ import annotations

import contextlib
import os
import stat
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

from ros_isolated_test.domain_coordinator.flock import try_lock, wait_lock
from ros_isolated_test.domain_coordinator.lock_dir import (
    LockDirError,
    ensure_lock_dir,
    owned_file,
    read_small_file,
)
from ros_isolated_test.domain_coordinator.records import (
    LATEST_TIME,
    LONG_TEXT,
    SHORT_TEXT,
    iso_time,
    parse_record,
    record_pid,
    record_text,
    record_time,
    user_name,
)
from ros_isolated_test.process import proc
from ros_isolated_test.text import display_text, json_string, shell_join

QUEUE_DIR = "queue"
_TICKET = ".ticket"
#: Before ``.ticket`` in the name of a ticket that asks for resources: the others are
#: ID-only, and a runner reads no record to know that.
RESOURCE_MARK = ".r"


class Ticket:
    """A runner's place in the queue, held until it gets an ID or gives up."""

    def __init__(self, queue: Queue, path: Path, fd: int) -> None:
        self.queue = queue
        self.path = path
        #: Names sort by arrival time, whichever folder holds them.
        self.name = path.name
        self.fd = fd

    def ahead(self) -> int:
        """Live tickets older than this one, in every queue folder."""
        return sum(1 for path in self.queue.live_tickets() if path.name < self.name)

    def close(self) -> None:
        """Leave the queue (or give up the hold): the ticket goes, then its lock."""
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        os.close(self.fd)


class RunnerRecord:
    """A runner as its ticket's record shows it: a waiter in the queue, or a hold."""

    __slots__ = ("command", "host", "pid", "resources", "since", "user")

    def __init__(
        self, pid: int, user: str, command: str, since: float, host: str, resources: dict[str, int]
    ) -> None:
        self.pid = pid
        self.user = user
        self.command = command
        self.since = since
        self.host = host
        #: What it asks for besides an ID, or holds ({name: amount}; empty: nothing).
        self.resources = resources

    def as_dict(self) -> dict[str, object]:
        """The fields ``status --json`` shows of every runner, waiting or holding."""
        return {
            "pid": self.pid,
            "user": self.user,
            "command": self.command,
            "started": self.since,
            "host": self.host,
            "resources": dict(self.resources),
        }


class Waiter(RunnerRecord):
    """A runner waiting for an ID, as its ticket describes it."""

    __slots__ = ("position",)

    def __init__(
        self,
        position: int,
        pid: int,
        user: str,
        command: str,
        since: float,
        host: str,
        resources: dict[str, int] | None = None,
    ) -> None:
        super().__init__(pid, user, command, since, host, resources or {})
        #: 1 for the head of the queue, the next to get an ID.
        self.position = position

    @property
    def since_iso(self) -> str:
        """Local time the runner started waiting, to the second ("-" when unknown)."""
        return iso_time(self.since)

    def as_dict(self) -> dict[str, object]:
        """The fields ``status --json`` shows, its place in the queue first."""
        return {"position": self.position, **super().as_dict()}


def _record(command: Sequence[str] | None, extra: str = "") -> bytes:
    """The ticket record of this waiter, as JSON (no ``json`` import: a runner writes it).

    ``extra``: more fields, already JSON (``"name": value, ...``).
    """
    words = list(command) if command is not None else list(sys.argv)
    fields = (
        f'"pid": {os.getpid()}',
        f'"user": {json_string(user_name(os.getuid()))}',
        f'"command": {json_string(shell_join(words))}',
        f'"started": {time.time()!r}',
        f'"host": {json_string(os.uname().nodename)}',
        *((extra,) if extra else ()),
    )
    return ("{" + ", ".join(fields) + "}").encode("utf-8")


def _from_name(name: str, limit: int) -> tuple[int, float]:
    """The PID (below ``limit``, pid_max) and arrival time a ticket's name holds.

    0 for what it does not hold.
    """
    arrived, _dash, pid_text = name[: -len(_TICKET)].partition("-")
    pid_text = pid_text.removesuffix(RESOURCE_MARK)
    pid = 0
    if pid_text.isascii() and pid_text.isdigit():  # int() refuses some other digits
        pid = record_pid(int(pid_text), limit) or 0
    since = 0.0
    if arrived.isascii() and arrived.isdigit():
        nanoseconds = int(arrived)
        # Compared first: a 200-digit number divided into a float raises OverflowError.
        if 0 < nanoseconds <= LATEST_TIME * 1e9:
            since = nanoseconds / 1e9
    return pid, since


def _unusable(path: Path, own: bool) -> str | None:
    """Why ``path`` cannot take our tickets, or None when it can.

    Our own folder must be ours. The shared one may be anyone's (the first runner to
    queue creates it), but then with the sticky bit, like /tmp: without it anyone could
    remove our tickets.
    """
    try:
        info = os.lstat(path)
    except OSError as error:
        return error.strerror or "cannot be read"
    if stat.S_ISLNK(info.st_mode):
        return "a symlink"
    if not stat.S_ISDIR(info.st_mode):
        return "not a directory"
    if info.st_uid != os.getuid() and (own or not info.st_mode & stat.S_ISVTX):
        return "a directory of another user" + ("" if own else " without the sticky bit")
    if not os.access(path, os.W_OK | os.X_OK, follow_symlinks=False):
        return "not writable by this user"
    return None


class Queue:
    """The waiting runners of one lock directory."""

    def __init__(self, lock_dir: Path, folder: str = QUEUE_DIR) -> None:
        self.lock_dir = lock_dir
        self.folder = folder
        #: The shared queue folder, and this user's own for when it was planted.
        self.path = lock_dir / folder
        self.own_path = lock_dir / f"{folder}.uid{os.getuid()}"
        #: Set by :meth:`ticket` when the shared folder was unusable: one line to show.
        self.problem: str | None = None

    def folders(self) -> list[Path]:
        """Every queue folder: the shared one and each user's own (never through a link)."""
        found = [self.path]
        with contextlib.suppress(OSError):
            prefix = f"{self.folder}.uid"
            for entry in os.scandir(self.lock_dir):
                if entry.name.startswith(prefix):
                    found.append(Path(entry.path))
        return [path for path in found if _is_directory(path)]

    def live_tickets(self) -> list[Path]:
        """The tickets whose waiter is alive, first come first; our own dead ones are removed."""
        live: list[Path] = []
        for folder in self.folders():
            with contextlib.suppress(OSError):
                for entry in os.scandir(folder):
                    if not entry.name.endswith(_TICKET):
                        continue
                    path = Path(entry.path)
                    if self._held(path):
                        live.append(path)
                    elif owned_file(path):
                        with contextlib.suppress(OSError):
                            os.unlink(path)
        return sorted(live, key=lambda path: path.name)

    def shared_problem(self) -> str | None:
        """Why the shared queue folder cannot be used, for ``status`` (None: it can)."""
        if not os.path.lexists(self.path):
            return None  # the first runner to queue creates it
        why = _unusable(self.path, own=False)
        return None if why is None else _fallback_note(self.path, why, self.own_path, self.folder)

    def waiters(self) -> list[Waiter]:
        """Every live waiter, first in line first.

        A ticket without a readable record still counts: its name holds the PID and
        the arrival time.
        """
        found: list[Waiter] = []
        limit = proc.pid_max()
        for position, path in enumerate(self.live_tickets(), start=1):
            pid, since = _from_name(path.name, limit)
            command, host = "(no record)", ""
            try:
                owner = user_name(os.lstat(path).st_uid)
            except OSError:
                continue  # gone meanwhile: it got its ID
            try:
                data = parse_record(read_small_file(path))
            except (OSError, ValueError):  # unreadable, not a regular file, not UTF-8
                data = None
            wanted: dict[str, int] = {}
            if data is not None:
                # Field by field: a planted record cannot make a valid field disappear.
                command = record_text(data.get("command"), LONG_TEXT) or command
                host = record_text(data.get("host")) or host
                pid = record_pid(data.get("pid"), limit) or pid
                since = record_time(data.get("started")) or since
                wanted = record_amounts(data.get("resources"))
            found.append(Waiter(position, pid, owner, command, since, host, wanted))
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
    def ticket(
        self, command: Sequence[str] | None = None, extra: str = "", marked: bool = False
    ) -> Iterator[Ticket | None]:
        """Take a place at the end of the queue for the ``with`` block.

        ``command`` is recorded in the ticket for ``status`` (default: this process's
        own command line). When the shared folder is unusable (something planted there)
        the ticket goes into this user's own folder and :attr:`problem` says so; when
        that fails too, it yields None: the runner then still waits, only without the
        first-come-first-served order. ``extra`` adds fields to the record; ``marked``
        names the ticket as one asking for resources (:data:`RESOURCE_MARK`).
        """
        ticket = self.enter(command, extra, marked)
        if ticket is None:
            yield None
            return
        try:
            yield ticket
        finally:
            ticket.close()

    def enter(
        self, command: Sequence[str] | None = None, extra: str = "", marked: bool = False
    ) -> Ticket | None:
        """A ticket held until :meth:`Ticket.close` (see :meth:`ticket`); None if none was made."""
        mark = RESOURCE_MARK if marked else ""
        name = f"{time.time_ns():020d}-{os.getpid()}{mark}{_TICKET}"
        record = _record(command, extra)
        why = self._prepare(self.path, own=False)
        held = self._take(self.path / name, record) if why is None else None
        if held is None:
            why = why or "tickets cannot be created in it"
            own_why = self._prepare(self.own_path, own=True)
            held = self._take(self.own_path / name, record) if own_why is None else None
            self.problem = _fallback_note(
                self.path, why, self.own_path if held else None, self.folder
            )
        if held is None:
            return None
        path, fd = held
        return Ticket(self, path, fd)

    @staticmethod
    def _prepare(folder: Path, own: bool) -> str | None:
        """Create the folder if missing; why it cannot take our tickets, or None."""
        try:
            if own:
                with contextlib.suppress(FileExistsError):
                    os.mkdir(folder, 0o755)  # others read it: tickets must be seen held
            else:
                ensure_lock_dir(folder)  # shared: mode 1777, like the lock directory
        except (OSError, LockDirError):
            pass  # _unusable says what is wrong
        return _unusable(folder, own)

    @staticmethod
    def _take(path: Path, record: bytes) -> tuple[Path, int] | None:
        """A locked ticket at ``path`` with our record: (path, descriptor), or None."""
        fd: int | None = None
        # Locked under a name nobody looks at, then renamed into the queue: an
        # unlocked ticket would look dead and could be removed by another runner.
        staging = path.with_name(f".{path.name}.new")
        try:
            fd = os.open(
                staging, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644
            )
            with contextlib.suppress(OSError):
                os.fchmod(fd, 0o644)  # others must open it to see that it is held
            with contextlib.suppress(OSError):
                # Our own new file (O_EXCL): written before it appears in the queue. A
                # full disk only costs status the record, never the place in line.
                os.write(fd, record)
            wait_lock(fd)
            os.rename(staging, path)
        except OSError:
            if fd is not None:
                os.close(fd)
                with contextlib.suppress(OSError):
                    os.unlink(staging)
            return None
        return path, fd


def _is_directory(path: Path) -> bool:
    try:
        return stat.S_ISDIR(os.lstat(path).st_mode)
    except OSError:
        return False


def _fallback_note(shared: Path, why: str, own: Path | None, folder: str = QUEUE_DIR) -> str:
    """One line naming the planted path and what the runners do about it."""
    if folder != QUEUE_DIR:
        where = (
            f"runners of this user keep their holds in {own} instead"
            if own is not None
            else "this runner could not record its hold"
        )
        kind = f"{folder} folder"
    else:
        where = (
            f"runners of this user queue in {own} instead (first come, first served among them)"
            if own is not None
            else "runners wait without first come, first served"
        )
        kind = "queue folder"
    return (
        f"the shared {kind} {display_text(str(shared), SHORT_TEXT)} is unusable "
        f"({why}; planted?): {where}; remove it to restore the shared {kind}"
    )


def record_amounts(value: object) -> dict[str, int]:
    """A record's resource amounts ({name: amount}) as far as they are valid; {} otherwise.

    A planted record may hold anything: names and amounts as a request allows, at most
    16 of them.
    """
    from ros_isolated_test.domain_coordinator.resources import MAX_AMOUNT, MAX_NAME, MAX_NAMES

    if not isinstance(value, dict):
        return {}
    amounts: dict[str, int] = {}
    for name, amount in list(value.items())[:MAX_NAMES]:
        if (
            isinstance(name, str)
            and 0 < len(name) <= MAX_NAME
            and name.isascii()
            and name.replace("_", "").replace("-", "").isalnum()
            and name == name.lower()
            and type(amount) is int
            and 0 < amount <= MAX_AMOUNT
        ):
            amounts[name] = amount
    return amounts
