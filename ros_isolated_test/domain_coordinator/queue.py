"""First come, first served among runners waiting for a domain ID.

Each waiter holds a flock on a ticket file named after its arrival time; a runner
may take an ID only when no live ticket is older than its own. A waiter that dies
leaves its ticket unlocked, and the next runner to look removes or ignores it.
"""

from __future__ import annotations

import contextlib
import os
import stat
import time
from collections.abc import Iterator
from pathlib import Path

from ros_isolated_test.domain_coordinator.flock import try_lock, wait_lock
from ros_isolated_test.domain_coordinator.holder import owned_file
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
    def ticket(self) -> Iterator[Ticket | None]:
        """Take a place at the end of the queue for the ``with`` block.

        Yields None when the queue folder is unusable (something planted there): the
        runner then still waits, only without the first-come-first-served order.
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
                staging, os.O_RDONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644
            )
            with contextlib.suppress(OSError):
                os.fchmod(fd, 0o644)  # others must open it to see that it is held
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
