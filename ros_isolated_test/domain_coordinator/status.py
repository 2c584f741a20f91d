"""What ``ros-isolated-test status`` reports: every domain ID in use on this machine.

An ID is in use when a runner holds its lock, when something binds its TCP port
(upstream's ``domain_coordinator``, Kilted's ``rmw_test_fixture``, another program),
when a DDS participant is bound to its UDP ports, or when a live process carries
it in ROS_DOMAIN_ID (a test that outlived its runner, a shell's export): a squatter,
or while a block record names a live survivor of its last test (one the runner could
not end).
Runners waiting for an ID (their tickets in the queue) are listed apart, then the machine
resources runners hold: :func:`machine_status` reads all of it once, for the table.

Everything shown comes display-safe from here: records are validated as they are read
(see ``records``), and a squatter's or survivor's command line, which any process can
set, has its control characters escaped like a record's.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from ros_isolated_test.domain_coordinator import (
    participants,
    port_guard,
    records,
    squatters,
    upstream,
)
from ros_isolated_test.domain_coordinator.block import blocking_survivors
from ros_isolated_test.domain_coordinator.lock_files import probe_lock
from ros_isolated_test.domain_coordinator.queue import Queue, Waiter
from ros_isolated_test.domain_coordinator.resource_holds import Hold, holds
from ros_isolated_test.domain_coordinator.resources import capacity_for
from ros_isolated_test.process import proc
from ros_isolated_test.text import display_text

_LOCK_NAME = re.compile(r"domain-([0-9]+)(?:\.uid[0-9]+)?\.lock")


@dataclass(frozen=True)
class DomainUse:
    """One ID in use, and by what.

    ``via`` is ``lock`` (a runner), ``port``, ``participant``, ``environment`` (a
    squatter), ``survivor``, or the upstream coordinator whose port holds it and whose
    process set the ID for what it started (``upstream.COLCON``, ``UPSTREAM``,
    ``FIXTURE``: the holder is that tool's process); ``ports`` are a participant's UDP
    ports (its owner is not known). ``replaced``: a runner's test was given this ID in
    place of a tool's (``14 (colcon's domain-ID coordinator)``), else empty.
    """

    domain_id: int
    via: str
    holder: records.Holder | None
    ports: tuple[int, ...] = ()
    replaced: str = ""


def domain_uses(lock_dir: Path, pool: tuple[int, ...]) -> list[DomainUse]:
    """Every ID in use: locks in the directory (any pool), ports and squatters of the pool.

    Runners of other users may use other pools, so every lock file counts, not only
    the caller's pool. Probing a lock takes it for an instant when it is free; a runner
    that looks at that moment moves on to the next ID, so probing never fails a test.
    """
    candidates = set(pool)
    with contextlib.suppress(OSError):
        for entry in os.scandir(lock_dir):
            match = _LOCK_NAME.fullmatch(entry.name)
            if match:
                candidates.add(int(match.group(1)))
    uses: list[DomainUse] = []
    found = squatters.scan(candidates)
    bound = participants.bound_domains()
    # A survivor still carries an ID in its environment: listed once, as a survivor.
    survivors = {
        domain_id: _unique(blocking_survivors(lock_dir, domain_id)) for domain_id in candidates
    }
    named = {survivor.pid for found_here in survivors.values() for survivor in found_here}
    for domain_id in sorted(candidates):
        holders: set[int] = set()
        tools: set[int] = set()  # squatters whose ID a tool set and holds for them
        if probe_lock(lock_dir, domain_id):
            found_records = records.read_records(lock_dir, domain_id)
            holder = found_records[0] if found_records else None
            replaced = "" if holder is None else _replaced(holder.pid, domain_id)
            uses.append(DomainUse(domain_id, "lock", holder, replaced=replaced))
            holders = {record.pid for record in found_records}
        elif port_guard.port_is_taken(domain_id):
            setters = _setters(found.get(domain_id, []), domain_id)
            tools = set(setters)
            uses.extend(_tool_use(setter) for setter in _unique_setters(setters.values()))
            if not setters:
                uses.append(DomainUse(domain_id, "port", None))
        elif domain_id in bound:  # a holder's own test is a participant too: not listed
            uses.append(DomainUse(domain_id, "participant", None, tuple(bound[domain_id])))
        for squatter in found.get(domain_id, ()):
            if squatter.pid in named:
                continue  # a survivor, listed below
            if holders & squatters.ancestors(squatter.pid):
                continue  # the holder's own test, not a squatter
            if squatter.pid in tools:
                continue  # started by a tool that holds the ID: listed as that tool
            uses.append(
                DomainUse(
                    domain_id,
                    "environment",
                    records.Holder(
                        domain_id=domain_id,
                        pid=squatter.pid,
                        user=squatter.user,
                        command=display_text(squatter.command),
                        started=squatter.started,
                        host="",
                    ),
                )
            )
        for survivor in survivors[domain_id]:
            uses.append(DomainUse(domain_id, "survivor", _survivor(domain_id, survivor)))
    return uses


def _setters(found: list[squatters.Squatter], domain_id: int) -> dict[int, upstream.Setter]:
    """Each process carrying ``domain_id`` that a tool holding it gave it, by PID."""
    setters: dict[int, upstream.Setter] = {}
    for squatter in found:
        setter = upstream.setter_of(squatter.pid)
        if setter is not None and setter.domain_id == domain_id:
            setters[squatter.pid] = setter
    return setters


def _unique_setters(setters: Iterable[upstream.Setter]) -> list[upstream.Setter]:
    """Each tool once, though it started several processes on its ID."""
    return list({setter.pid: setter for setter in setters}.values())


def _tool_use(setter: upstream.Setter) -> DomainUse:
    """An ID an upstream coordinator holds, named by its process (colcon, upstream's runner)."""
    stat = proc.read_stat(setter.pid)
    return DomainUse(
        setter.domain_id,
        setter.kind,
        records.Holder(
            domain_id=setter.domain_id,
            pid=setter.pid,
            user=records.user_name(proc.owner_uid(setter.pid)),
            command=display_text(setter.command or "?"),
            started=proc.started_at(stat) if stat is not None else 0.0,
            host="",
        ),
    )


def _replaced(pid: int, domain_id: int) -> str:
    """The tool's ID that runner ``pid``'s test got ``domain_id`` in place of, if any.

    The runner started with the tool's ID in its environment (it replaced it for the
    test), and the tool still holds it.
    """
    value = upstream.variable(proc.environ(pid))
    if value is None or squatters.domain_value(value) == domain_id:
        return ""
    setter = upstream.setter_of(pid, value)
    return "" if setter is None else f"{setter.value} ({setter.short})"


def _unique(survivors: list[proc.Stat]) -> list[proc.Stat]:
    """Each process once, though several block records (or users) may name it."""
    return list({stat.pid: stat for stat in survivors}.values())


def _survivor(domain_id: int, survivor: proc.Stat) -> records.Holder:
    """A survivor of the ID's last test, described like a holder."""
    return records.Holder(
        domain_id=domain_id,
        pid=survivor.pid,
        user=records.user_name(proc.owner_uid(survivor.pid)),
        command=display_text(proc.cmdline(survivor.pid) or f"({survivor.name})"),
        started=proc.started_at(survivor),
        host="",
    )


def describe_holders(lock_dir: Path, pool: tuple[int, ...], limit: int = 8) -> str:
    """A short line naming who uses the pool, for waiting and exhaustion messages."""
    return pool_usage(lock_dir, pool, limit)[1]


def pool_usage(lock_dir: Path, pool: tuple[int, ...], limit: int = 8) -> tuple[int, str]:
    """How many IDs of the pool are held, and the line of :func:`describe_holders`."""
    wanted = set(pool)
    parts: list[str] = []
    items = [item for item in domain_uses(lock_dir, pool) if item.domain_id in wanted]
    held = len({item.domain_id for item in items})
    for item in items[:limit]:
        if item.holder is not None:
            kind = {"environment": "squatter ", "survivor": "survivor "}.get(item.via, "")
            kind = f"{upstream.SHORT[item.via]} " if item.via in upstream.SHORT else kind
            parts.append(
                f"{item.domain_id}: {kind}pid {item.holder.pid} ({item.holder.user}) "
                f"{item.holder.command[:60]}"
            )
        else:
            parts.append(f"{item.domain_id}: {_anonymous(item)}")
    if len(items) > limit:
        parts.append(f"and {len(items) - limit} more")
    return held, "; ".join(parts) or "see ros-isolated-test status"


def _anonymous(item: DomainUse) -> str:
    """What holds an ID when no process is named: a port, a participant's UDP ports."""
    if item.via == "port":
        return "port taken"
    if item.via == "participant":
        return f"DDS participant on UDP {_ports(item.ports)}"
    return item.via


def _ports(ports: tuple[int, ...], limit: int = 4) -> str:
    shown = ", ".join(str(port) for port in ports[:limit])
    return shown + (f" and {len(ports) - limit} more" if len(ports) > limit else "")


def anonymous_holder(item: DomainUse) -> str:
    """The line ``status`` shows for an ID no holder record or process names."""
    if item.via == "lock":
        return "held (no holder record)"
    if item.via == "participant":
        return f"a DDS participant (UDP ports {_ports(item.ports)}) outside any runner"
    return "port 32768+ID taken (upstream domain_coordinator or another program)"


@dataclass(frozen=True)
class MachineStatus:
    """Everything ``status`` shows, read once: IDs in use, waiters, resources held."""

    lock_dir: Path
    uses: list[DomainUse]
    waiters: list[Waiter]
    #: Why the shared queue folder cannot be used (planted), or None.
    queue_problem: str | None
    holds: list[Hold]
    #: The capacity to show: this shell's, then what holders were given for other names.
    capacity: dict[str, int]
    #: Whether resources are in play (held, asked for, or a capacity set here).
    in_play: bool


def machine_status(
    lock_dir: Path, pool: tuple[int, ...], configured: dict[str, int]
) -> MachineStatus:
    """Read what ``status`` shows; ``configured`` is the capacity this shell's settings give."""
    uses = domain_uses(lock_dir, pool)
    queue = Queue(lock_dir)
    waiters = queue.waiters()
    # A planted shared queue folder: runners still queue (per user), but whoever planted
    # it should be found.
    problem = queue.shared_problem()
    held_resources = holds(lock_dir)
    # The capacity this shell's settings give, with what runners holding something were
    # given for names it does not set (they may have been started elsewhere).
    capacity = capacity_for(["cpu", "mem"], configured)
    for hold in held_resources:
        for name, amount in hold.capacity.items():
            capacity.setdefault(name, amount)
    capacity.update(configured)
    in_play = bool(held_resources or configured or any(w.resources for w in waiters))
    return MachineStatus(lock_dir, uses, waiters, problem, held_resources, capacity, in_play)
