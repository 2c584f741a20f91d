"""Reserving a domain ID: one flock'ed file per ID, plus upstream's TCP port.

The kernel drops a flock when the last descriptor of its open file closes, so an ID
comes free however its holder dies (exit, crash, SIGKILL): no stale-lock cleanup, no
timeouts, no daemon. The descriptor is close-on-exec: the test does not inherit it.

Every holder also binds the ID's TCP port, and that port is the final arbiter: when a
lock file was planted by another user (a symlink, a file we may not open) a runner
falls back to a lock file of its own for that ID and still cannot collide.

The lock is filelock's (see ``flock``): a filelock ``FileLock`` on an ID's lock file
and our reservation of that ID exclude each other. An ID whose last test left
survivors stays taken while they live (see ``block``), as does one a DDS participant
is bound to (``participants``) or, after a holder died holding it, one a process
still carries in ROS_DOMAIN_ID (``escaped``).

A runner that asks for machine resources (``resource_holds``) takes them together with its
ID, all or nothing, and gives both back together. Waiting for them in line, first come,
first served, is ``waiting``'s policy: this module only takes and gives back.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

from ros_isolated_test.domain_coordinator import participants, port_guard, records
from ros_isolated_test.domain_coordinator.block import blocking_survivors, write_block
from ros_isolated_test.domain_coordinator.escaped import escaped_processes
from ros_isolated_test.domain_coordinator.flock import try_lock as _try_flock
from ros_isolated_test.domain_coordinator.lock_dir import (
    LockDirError,
    UnusableLockFile,
    ensure_lock_dir,
    lock_dir_from_env,
    open_lock_file,
)
from ros_isolated_test.domain_coordinator.lock_files import lock_path, own_lock_path
from ros_isolated_test.domain_coordinator.pool import pool_from_env
from ros_isolated_test.domain_coordinator.queue import Queue, Ticket
from ros_isolated_test.domain_coordinator.resources import describe
from ros_isolated_test.domain_coordinator.waiting import Waiting
from ros_isolated_test.process import proc


def release_stamp(lock_dir: Path, domain_id: int) -> Path:
    """A file whose mtime says when this user last released the ID (least recently used)."""
    return lock_dir / f"domain-{domain_id}.uid{os.getuid()}.released"


TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    import _socket


class Reservation:
    """A held domain ID. Release it with :meth:`release` (or leave the ``with`` block)."""

    __slots__ = (
        "domain_id",
        "holding",
        "lock_dir",
        "lock_fd",
        "port",
        "record",
        "released",
        "unclean",
        "waited",
        "waited_resources",
    )

    def __init__(
        self,
        domain_id: int,
        lock_fd: int | None,
        port: _socket.socket,
        record: Path | None,
        lock_dir: Path,
    ) -> None:
        self.domain_id = domain_id
        #: None when every lock file for the ID was planted: the port alone guards it then.
        self.lock_fd = lock_fd
        self.port = port
        self.record = record
        self.lock_dir = lock_dir
        self.released = False
        #: Set when survivors could not be recorded: the release then says nothing is left
        #: of the test only if that is true (see :meth:`release`).
        self.unclean = False
        #: The hold of the resources taken with the ID (``resource_holds``), given back with it.
        self.holding: Ticket | None = None
        #: Seconds spent waiting for the ID (and the resources) before it was held; of
        #: those, the ones when the resources asked for were short (the rest: no ID free,
        #: or an earlier waiter's turn).
        self.waited = 0.0
        self.waited_resources = 0.0

    def __repr__(self) -> str:
        return f"Reservation(domain_id={self.domain_id}, released={self.released})"

    def block_for(self, processes: Iterable[proc.Stat]) -> Path:
        """Keep the ID from every runner while any of ``processes`` lives, after release.

        For survivors of the test: processes the runner could not end. Call it before
        :meth:`release`, while no other runner can take the ID. The resources held with
        the ID stay held as long (``resource_holds.keep_for``). Raises OSError when the block
        cannot be recorded.
        """
        processes = list(processes)
        try:
            path = write_block(self.lock_dir, self.domain_id, processes)
            if self.holding is not None:
                from ros_isolated_test.domain_coordinator import resource_holds

                resource_holds.keep_for(self.holding, processes)
        except OSError:
            self.unclean = True
            raise
        return path

    def release(self) -> None:
        """Give the ID back: record first, so ``status`` never names a holder that left.

        A clean release (record removed, stamp touched) tells the next holder nothing
        of the test is left. When survivors live that no block record names (it could
        not be written), the record stays, refreshed, and no stamp is touched: the next
        holder then looks for them in /proc, as after a holder that died holding the ID.
        """
        if self.released:
            return
        self.released = True
        if self.unclean:
            if self.record is None or not records.refresh(self.record):
                records.mark_held(self.lock_dir, self.domain_id)
            self._let_go()
            return
        if self.record is not None:
            records.remove_record(self.record)
        with contextlib.suppress(OSError):
            stamp = release_stamp(self.lock_dir, self.domain_id)
            flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
            fd = os.open(stamp, flags, 0o644)
            try:
                info = os.fstat(fd)
                # Only our own stamp: a file planted under its name is left alone.
                if stat.S_ISREG(info.st_mode) and info.st_uid == os.getuid():
                    os.utime(fd)
            finally:
                os.close(fd)
        self._let_go()

    def _let_go(self) -> None:
        if self.holding is not None:
            self.holding.close()
        self.port.close()
        if self.lock_fd is not None:
            os.close(self.lock_fd)


class ResourceHold:
    """Resources held without a domain ID (isolation disabled): released like a reservation."""

    __slots__ = ("holding", "released", "waited", "waited_resources")

    def __init__(self, holding: Ticket) -> None:
        self.holding = holding
        self.waited = self.waited_resources = 0.0
        self.released = False

    def block_for(self, processes: Iterable[proc.Stat]) -> Path:
        """Keep the resources held while any of ``processes`` lives (see Reservation's)."""
        from ros_isolated_test.domain_coordinator import resource_holds

        return resource_holds.keep_for(self.holding, processes)

    def release(self) -> None:
        if not self.released:
            self.released = True
            self.holding.close()


def _flock(fd: int) -> int | None:
    try:
        if _try_flock(fd):
            return fd
    except OSError:
        pass
    os.close(fd)
    return None


#: try_lock's answer when every lock file for the ID was planted.
PORT_ONLY = -1


def try_lock(lock_dir: Path, domain_id: int) -> int | None:
    """One non-blocking attempt at the ID's lock: the held descriptor, or None if busy.

    A planted shared lock file is replaced by this user's own lock file for the ID, and
    if that was planted too, by the port alone (:data:`PORT_ONLY`): the port every holder
    binds keeps two holders of one ID apart whichever file they use, so nobody can deny
    an ID by planting files.
    """
    for path in (lock_path(lock_dir, domain_id), own_lock_path(lock_dir, domain_id)):
        try:
            return _flock(open_lock_file(path))
        except UnusableLockFile:
            continue
    return PORT_ONLY


def _released_at(lock_dir: Path) -> dict[int, float]:
    """When each ID was last released by anyone, from one directory listing."""
    released: dict[int, float] = {}
    with contextlib.suppress(OSError):
        for entry in os.scandir(lock_dir):
            name = entry.name
            if name.startswith("domain-") and name.endswith(".released"):
                with contextlib.suppress(ValueError, OSError):
                    domain_id = int(name[len("domain-") :].split(".", 1)[0])
                    mtime = entry.stat(follow_symlinks=False).st_mtime
                    released[domain_id] = max(released.get(domain_id, 0.0), mtime)
    return released


def _spread(remaining: list[int], released: dict[int, float]) -> list[int]:
    """``remaining`` with its equally old head rotated by our PID.

    Runners started together find the same ID taken and would all try the same next
    one; among IDs no older than each other (a fresh machine: all of them) each goes
    on from a place of its own. Least recently used still comes first.
    """
    age = released.get(remaining[0], 0.0)
    ties = 1
    while ties < len(remaining) and released.get(remaining[ties], 0.0) == age:
        ties += 1
    turn = os.getpid() % ties
    return remaining[turn:ties] + remaining[:turn] + remaining[ties:]


class DomainCoordinator:
    """Hands out domain IDs from a pool, machine-wide, through a shared lock directory."""

    def __init__(
        self,
        lock_dir: Path | None = None,
        pool: Sequence[int] | None = None,
        resources: dict[str, int] | None = None,
        capacity: dict[str, int] | None = None,
    ) -> None:
        self.lock_dir = lock_dir if lock_dir is not None else lock_dir_from_env()
        self.pool = tuple(pool) if pool is not None else pool_from_env()
        #: What every reservation of this coordinator holds besides its ID (``resource_holds``).
        self.resources = dict(resources or {})
        #: The capacity of those resources (settings): every runner must be given the same.
        self.capacity = dict(capacity or {})

    def candidates(self, released: dict[int, float] | None = None) -> list[int]:
        """The pool, least recently released first.

        Least recently used: discovery data a finished test left behind has the most
        time to expire before its domain is used again.
        """
        released = _released_at(self.lock_dir) if released is None else released
        return sorted(self.pool, key=lambda domain_id: released.get(domain_id, 0.0))

    def try_reserve(self, command: Sequence[str]) -> Reservation | None:
        """A free ID of the pool, held; None when all are taken.

        An ID counts as free only when its lock and its TCP port can both be taken (so
        upstream's coordinators on this machine, Jazzy's and Kilted's, are respected),
        no survivor of its last test lives (a block record; one lstat when there is
        none), no DDS participant on it is bound in this network namespace (one read of
        the UDP tables, when the first ID is held: runners that find every ID taken
        never pay it) and, only when its last holder died holding it, no live process
        carries it in ROS_DOMAIN_ID (see ``escaped``). Nothing here grows with the
        number of processes on the machine, except that last look, for that one ID.
        """
        ensure_lock_dir(self.lock_dir)
        bound: dict[int, list[int]] | None = None
        released = _released_at(self.lock_dir)
        remaining = self.candidates(released)
        spread = False
        while remaining:
            domain_id = remaining.pop(0)
            found = try_lock(self.lock_dir, domain_id)
            if found is None:
                if not spread and remaining:
                    spread = True
                    remaining = _spread(remaining, released)
                continue
            lock_fd = None if found == PORT_ONLY else found
            port = port_guard.claim_port(domain_id)
            # Survivors of the ID's last test: checked once the ID is held, so a block
            # written just before its holder let go is seen.
            if port is not None and blocking_survivors(self.lock_dir, domain_id, clean=True):
                port.close()
                port = None
            if port is not None:
                if bound is None:
                    bound = participants.bound_domains()
                if domain_id not in bound and not escaped_processes(self.lock_dir, domain_id):
                    try:
                        record: Path | None = records.write_record(
                            self.lock_dir, domain_id, command
                        )
                    except OSError:
                        # An empty record, if even that: it still says "held" should we die.
                        record = records.mark_held(self.lock_dir, domain_id)
                    if record is None:
                        port.close()
                        if lock_fd is not None:
                            os.close(lock_fd)
                        raise LockDirError(
                            f"cannot record the holder of ROS_DOMAIN_ID {domain_id} in "
                            f"{self.lock_dir} (a runner that dies must leave that trace); free "
                            "space there, or point ROS_ISOLATED_TEST_LOCK_DIR elsewhere"
                        )
                    return Reservation(domain_id, lock_fd, port, record, self.lock_dir)
                port.close()
            if lock_fd is not None:
                os.close(lock_fd)
        return None

    def reserve_if_free(self, command: Sequence[str]) -> Reservation | None:
        """An ID free now, held; None when none is, or an earlier waiter is to have it.

        Never waits, and never takes an ID a queued runner waits for: for a test in
        namespaces of its own, which runs whether it gets one or not (the ID only keeps
        ``status`` and its result meaningful). Holds no resources (see ``hold_resources``).
        """
        ensure_lock_dir(self.lock_dir)
        queue = Queue(self.lock_dir)
        waiting = Waiting(self.lock_dir, self.pool, self.resources, self.capacity)
        if queue.waiting() and waiting.id_ahead(queue, None):
            return None
        return self.try_reserve(command)

    def acquire(
        self,
        command: Sequence[str],
        wait_timeout: float = 0.0,
        on_wait: Callable[[str], None] | None = None,
    ) -> Reservation:
        """Reserve an ID (and the resources), waiting first come, first served while taken."""
        taken = self._wait(command, wait_timeout, on_wait, domain=True)
        assert isinstance(taken, Reservation)
        return taken

    def hold_resources(
        self,
        command: Sequence[str],
        wait_timeout: float = 0.0,
        on_wait: Callable[[str], None] | None = None,
    ) -> ResourceHold:
        """Hold the resources without an ID (isolation disabled), waiting like :meth:`acquire`."""
        taken = self._wait(command, wait_timeout, on_wait, domain=False)
        assert isinstance(taken, ResourceHold)
        return taken

    def _wait(
        self,
        command: Sequence[str],
        wait_timeout: float,
        on_wait: Callable[[str], None] | None,
        domain: bool,
    ) -> Reservation | ResourceHold:
        """Take in turn (``waiting`` keeps the line), each try by :meth:`_take`."""
        waiting = Waiting(self.lock_dir, self.pool, self.resources, self.capacity)

        def take(wanted: bool) -> Reservation | ResourceHold | None:
            return self._take(command, wanted)

        taken = waiting.wait(command, wait_timeout, on_wait, domain, take)
        assert isinstance(taken, (Reservation, ResourceHold))
        return taken

    def _take(self, command: Sequence[str], domain: bool) -> Reservation | ResourceHold | None:
        """One try at what this coordinator holds, when the waiting says it is our turn.

        Without resources: a free ID. With them (under their mutex): the ID when one is
        asked for, then the resources, together or nothing.
        """
        if not self.resources:
            return self.try_reserve(command)
        reservation = self.try_reserve(command) if domain else None
        if domain and reservation is None:
            return None
        # Only a runner that asks for resources loads their rules (so do ``waiting``'s).
        from ros_isolated_test.domain_coordinator import resource_holds

        holding = resource_holds.hold(
            self.lock_dir,
            command,
            self.resources,
            self.capacity,
            None if reservation is None else reservation.domain_id,
        )
        if holding is None:
            if reservation is not None:
                reservation.release()
            raise LockDirError(
                f"cannot record a hold of {describe(self.resources)} in {self.lock_dir} "
                "(a runner that dies must leave nothing held); free space there, or "
                "point ROS_ISOLATED_TEST_LOCK_DIR elsewhere"
            )
        if reservation is None:
            return ResourceHold(holding)
        reservation.holding = holding
        return reservation

    @contextlib.contextmanager
    def reserve(
        self,
        command: Sequence[str],
        wait_timeout: float = 0.0,
        on_wait: Callable[[str], None] | None = None,
    ) -> Iterator[Reservation]:
        """Hold an ID for the ``with`` block (see :meth:`acquire`)."""
        reservation = self.acquire(command, wait_timeout, on_wait)
        try:
            yield reservation
        finally:
            reservation.release()
