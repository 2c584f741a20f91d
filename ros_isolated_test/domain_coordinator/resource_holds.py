"""Holding machine resources (CPUs, memory, devices) machine-wide, like domain IDs.

A runner's hold is a ticket kept in the ``holds`` folder of the lock directory for the
test's whole life: a flock'ed file whose record says what it holds. The kernel drops the
flock however the runner dies, and a hold whose file is not locked counts for nothing,
so resources come free on any death, with no daemon and no timeout. Like the ID, they
stay taken while a survivor of the test lives (a process the runner could not end):
the runner keeps its hold in a survivor record before it lets go (:func:`keep_for`).

Taking is all-or-nothing, under one machine-wide lock (``resources.lock``): a runner
reads what the live holds use and what earlier waiters ask, decides, and takes its
domain ID and its resources together or nothing. Nobody waits holding part of what it
needs, so no two runners can deadlock.

The order (first come, first served, with claims): waiters are served in arrival order
per resource. A waiter may take its resources only when, for each one it asks, what is
free minus what every *earlier* waiter asks of it still covers its request: an earlier
large request is set aside first, so a stream of small ones never starves it. A domain
ID is taken only when no earlier waiter whose resources are free is still waiting for
one; a waiter held up by a resource therefore holds up nobody who asks for other things
or for an ID alone.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

from ros_isolated_test import not_run
from ros_isolated_test.atomic_file import write_atomically
from ros_isolated_test.domain_coordinator import records
from ros_isolated_test.domain_coordinator.flock import try_lock
from ros_isolated_test.domain_coordinator.lock_dir import (
    LockDirError,
    UnusableLockFile,
    open_lock_file,
    read_small_file,
)
from ros_isolated_test.domain_coordinator.queue import (
    RESOURCE_MARK,
    Queue,
    RunnerRecord,
    Ticket,
    record_amounts,
)
from ros_isolated_test.domain_coordinator.resources import describe, show_amount
from ros_isolated_test.process import proc

#: The folder of holds (and ``holds.uid<UID>`` for a user whose shared one was planted).
HOLD_DIR = "holds"
#: The lock every runner taking resources holds while it decides and takes.
MUTEX = "resources.lock"
#: How a hold kept for survivors is named: its ticket's name with this in place of
#: ``.ticket`` (never taken for a ticket, whose lock is what makes it live).
KEPT = ".survivors"

__all__ = [
    "HOLD_DIR",
    "CapacityConflictError",
    "Demand",
    "Hold",
    "Picture",
    "amounts_json",
    "holds",
    "keep_for",
    "mutex",
    "picture",
]


class CapacityConflictError(not_run.NotRun, RuntimeError):
    """Runners disagree on a capacity: the message names both and the fix."""


class Hold(RunnerRecord):
    """What one live runner holds, as its hold record says."""

    __slots__ = ("capacity", "domain_id", "survivors")

    def __init__(
        self,
        pid: int,
        user: str,
        command: str,
        since: float,
        host: str,
        resources: dict[str, int],
        capacity: dict[str, int],
        domain_id: int | None,
        survivors: tuple[int, ...] = (),
    ) -> None:
        super().__init__(pid, user, command, since, host, resources)
        #: The capacity its runner was given for what it holds: all runners must agree.
        self.capacity = capacity
        self.domain_id = domain_id
        #: For a hold kept after its runner left: the PIDs of the survivors still alive.
        self.survivors = survivors

    def as_dict(self) -> dict[str, object]:
        """The fields ``status --json`` shows (``survivors`` only for a kept hold)."""
        fields = {**super().as_dict(), "domain_id": self.domain_id}
        if self.survivors:
            fields["survivors"] = list(self.survivors)
        return fields

    def describe(self) -> str:
        """``pid 12 (alice) cpu=2,gpu=1 <command>``, for waiting messages."""
        if self.survivors:
            pids = ", ".join(map(str, self.survivors))
            who = f"survivor(s) {pids} of pid {self.pid}"
        else:
            who = f"pid {self.pid}"
        return f"{who} ({self.user}) {describe(self.resources)} {self.command[:60]}"


class Demand:
    """A waiter's request: resources, and whether it needs a domain ID too."""

    __slots__ = ("capacity", "domain", "name", "pid", "resources")

    def __init__(
        self,
        name: str,
        resources: dict[str, int],
        domain: bool,
        capacity: dict[str, int] | None = None,
        pid: int = 0,
    ) -> None:
        #: The ticket's name: names sort by arrival time.
        self.name = name
        self.resources = resources
        self.domain = domain
        self.capacity = capacity or {}
        self.pid = pid


def amounts_json(amounts: dict[str, int]) -> str:
    """{name: amount} as a JSON object (names are checked words: no escaping needed)."""
    return "{" + ", ".join(f'"{name}": {amount}' for name, amount in amounts.items()) + "}"


def _records(queue: Queue) -> Iterator[tuple[Path, dict[str, object]]]:
    """Each live ticket of ``queue`` with its record ({} when unreadable)."""
    for path in queue.live_tickets():
        data: dict[str, object] | None
        try:
            data = records.parse_record(read_small_file(path))
        except (OSError, ValueError):
            data = None
        yield path, data or {}


def holds(lock_dir: Path) -> list[Hold]:
    """Every live hold, oldest first, then every hold kept for survivors that still live.

    A hold nobody can read holds nothing.
    """
    found: list[Hold] = []
    limit = proc.pid_max()
    queue = Queue(lock_dir, HOLD_DIR)
    for path, data in _records(queue):
        hold = _hold(path, data, limit)
        if hold is not None:
            found.append(hold)
    return found + _kept(queue, limit)


def _hold(
    path: Path, data: dict[str, object], limit: int, survivors: tuple[int, ...] = ()
) -> Hold | None:
    try:
        owner = records.user_name(os.lstat(path).st_uid)
    except OSError:
        return None  # released meanwhile
    domain_id = data.get("domain_id")
    return Hold(
        pid=records.record_pid(data.get("pid"), limit) or 0,
        user=owner,
        command=records.record_text(data.get("command"), records.LONG_TEXT) or "(no record)",
        since=records.record_time(data.get("started")) or 0.0,
        host=records.record_text(data.get("host")) or "",
        resources=record_amounts(data.get("resources")),
        capacity=record_amounts(data.get("capacity")),
        domain_id=domain_id if type(domain_id) is int and 0 <= domain_id < 1000 else None,
        survivors=survivors,
    )


def keep_for(holding: Ticket, processes: Iterable[proc.Stat]) -> Path:
    """Keep a hold's resources while any of ``processes`` (survivors of its test) lives.

    Written beside the hold's ticket before the ticket is closed, so the resources are
    never free in between. The record is the hold's own, with each process named by PID
    and start time (a recycled PID is another process), this boot and our PID namespace
    (only there do those PIDs name them). Raises OSError when it cannot be written.
    """
    import json  # only when survivors are kept: never on a test's usual path

    data = records.parse_record(read_small_file(holding.path)) or {}
    data["survivors"] = [[process.pid, process.start] for process in processes]
    data["boot"] = proc.boot_id()
    data["pidns"] = proc.pid_namespace()
    stem = holding.path.name.removesuffix(".ticket")
    path = holding.path.with_name(stem + KEPT)
    write_atomically(path, json.dumps(data).encode("utf-8"))
    return path


def _kept(queue: Queue, limit: int) -> list[Hold]:
    """Holds kept for survivors: each counts while one of its processes lives.

    A record of another boot names nobody; one of another PID namespace is not ours to
    judge, and counts for nothing (as a block record). Our own records whose processes
    are all gone are removed.
    """
    found: list[Hold] = []
    for folder in queue.folders():
        with contextlib.suppress(OSError):
            paths = [Path(entry.path) for entry in os.scandir(folder) if entry.name.endswith(KEPT)]
            for path in sorted(paths, key=lambda item: item.name):
                hold = _kept_hold(path, limit)
                if hold is not None:
                    found.append(hold)
    return found


def _kept_hold(path: Path, limit: int) -> Hold | None:
    try:
        data = records.parse_record(read_small_file(path))
    except (OSError, ValueError):
        return None
    if data is None or data.get("pidns") != proc.pid_namespace():
        return None
    named = data.get("survivors")
    alive: list[int] = []
    if data.get("boot") == proc.boot_id() and isinstance(named, list):
        for item in named:
            if not (isinstance(item, list) and len(item) == 2):
                continue
            pid, start = item
            if records.record_pid(pid, limit) is None or type(start) is not int:
                continue
            if proc.living(pid, start) is not None:
                alive.append(pid)
    if not alive:
        records.remove_record(path)  # only when ours (a planted or another user's one stays)
        return None
    return _hold(path, data, limit, tuple(alive))


def demands(queue: Queue) -> list[Demand]:
    """Every live waiter's request, first come first. An ID-only ticket's record is not read."""
    found: list[Demand] = []
    limit = proc.pid_max()
    for path in queue.live_tickets():
        name = path.name
        if not name.endswith(RESOURCE_MARK + ".ticket"):
            found.append(Demand(name, {}, domain=True))
            continue
        data: dict[str, object] | None
        try:
            data = records.parse_record(read_small_file(path))
        except (OSError, ValueError):
            data = None
        data = data or {}
        found.append(
            Demand(
                name,
                record_amounts(data.get("resources")),
                domain=data.get("domain") is not False,
                capacity=record_amounts(data.get("capacity")),
                pid=records.record_pid(data.get("pid"), limit) or 0,
            )
        )
    return found


class Picture:
    """What is held and who waits, read once: the facts a decision is made from."""

    def __init__(self, held: list[Hold], waiting: list[Demand], capacity: dict[str, int]) -> None:
        self.held = held
        self.waiting = waiting
        #: Ours, and for names we were not told of, what their holders and waiters say.
        self.capacity = capacity
        used: dict[str, int] = {}
        for hold in held:
            for name, amount in hold.resources.items():
                used[name] = used.get(name, 0) + amount
        self.used = used

    def free(self, name: str) -> int:
        return self.capacity.get(name, 1) - self.used.get(name, 0)

    def may_go(self, mine: Demand, before: str | None) -> tuple[bool, bool]:
        """(whether our resources fit, whether an ID is ours to try for) now.

        ``before``: our ticket's name (waiters sorting before it are earlier); None for a
        newcomer without a ticket, behind everyone.
        """
        claimed: dict[str, int] = {}
        id_ahead = False
        for demand in self.waiting:
            if before is not None and demand.name >= before:
                break
            if demand.domain and self._fits(demand.resources, claimed):
                id_ahead = True
            for name, amount in demand.resources.items():
                claimed[name] = claimed.get(name, 0) + amount
        fits = self._fits(mine.resources, claimed)
        return fits, fits and not (mine.domain and id_ahead)

    def _fits(self, wanted: dict[str, int], claimed: dict[str, int]) -> bool:
        return all(
            self.free(name) - claimed.get(name, 0) >= amount for name, amount in wanted.items()
        )

    def shortage(self, wanted: dict[str, int]) -> str:
        """What of ``wanted`` is taken, and by whom, for the waiting message."""
        short = [
            f"{name} {show_amount(name, max(self.free(name), 0))} of "
            f"{show_amount(name, self.capacity.get(name, 1))} free"
            for name in sorted(wanted)
            if self.free(name) < wanted[name]
        ]
        users = [hold.describe() for hold in self.held if set(hold.resources) & set(wanted)]
        if not short:
            return "earlier waiters come first"
        shown = "; ".join(users[:6]) + (f" and {len(users) - 6} more" if len(users) > 6 else "")
        return f"{', '.join(short)} (held by {shown or 'nobody known'})"


def picture(
    lock_dir: Path,
    queue: Queue,
    wanted: dict[str, int],
    capacity: dict[str, int],
    before: str | None = None,
) -> Picture:
    """Read the holds and the queue; raise :class:`CapacityConflictError` on a disagreement.

    Only the capacity of what we ask for must agree: a runner told ``gpu=2`` while we
    were told ``gpu=1`` would hand out a GPU we think is taken. Compared with every hold
    and with waiters earlier than ``before`` (see :meth:`Picture.may_go`): the runner that
    came with another capacity is the one told, not everyone already waiting.
    """
    held = holds(lock_dir)
    waiting = demands(queue)
    known: dict[str, int] = {}
    others: list[tuple[str, int, int]] = [
        (name, amount, hold.pid) for hold in held for name, amount in hold.capacity.items()
    ]
    others += [
        (name, amount, demand.pid)
        for demand in waiting
        if before is None or demand.name < before
        for name, amount in demand.capacity.items()
    ]
    for name, amount, pid in others:
        if name in wanted and amount != capacity.get(name):
            raise CapacityConflictError(
                f"runners disagree on the capacity of {name}: this one has "
                f"{show_amount(name, capacity.get(name, 1))}, runner pid {pid} has "
                f"{show_amount(name, amount)}; give every runner the same "
                f"ROS_ISOLATED_TEST_CAPACITY (e.g. export it where ctest or colcon starts)"
            )
        known.setdefault(name, amount)
    return Picture(held, waiting, {**known, **capacity})


@contextlib.contextmanager
def mutex(lock_dir: Path) -> Iterator[bool]:
    """Try for the machine-wide lock for deciding and taking resources (a few milliseconds).

    Yields whether it is held. Never waits for it: whoever holds it (a runner stopped
    with Ctrl-Z, another user) must not keep a waiter past its --wait-timeout; a busy
    lock is one more reason to look again. When the shared lock file was planted, this
    user's own one stands in: runners of this user still exclude each other, and the
    claims still bind everyone.
    """
    fd: int | None = None
    for path in (lock_dir / MUTEX, lock_dir / f"resources.uid{os.getuid()}.lock"):
        try:
            fd = open_lock_file(path)
            break
        except (UnusableLockFile, LockDirError):
            continue
    if fd is None:
        yield True  # nothing to lock with: the claims alone keep the order
        return
    try:
        try:
            held = try_lock(fd)
        except OSError:
            held = True
        yield held
    finally:
        os.close(fd)


def hold(
    lock_dir: Path,
    command: Sequence[str],
    wanted: dict[str, int],
    capacity: dict[str, int],
    domain_id: int | None,
) -> Ticket | None:
    """Record our hold (under :func:`mutex`): the ticket to close on release; None if impossible."""
    extra = _asked(wanted, capacity) + f'"domain_id": {"null" if domain_id is None else domain_id}'
    return Queue(lock_dir, HOLD_DIR).enter(command, extra, marked=True)


def ticket_fields(wanted: dict[str, int], capacity: dict[str, int], domain: bool) -> str:
    """The extra record fields of a waiter's ticket that asks for resources."""
    return _asked(wanted, capacity) + f'"domain": {"true" if domain else "false"}'


def _asked(wanted: dict[str, int], capacity: dict[str, int]) -> str:
    """The request and the capacity it was made against, as record fields (and a comma)."""
    given = {name: capacity[name] for name in wanted}
    return f'"resources": {amounts_json(wanted)}, "capacity": {amounts_json(given)}, '
