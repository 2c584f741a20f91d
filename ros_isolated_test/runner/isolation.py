"""Holding what a run needs for as long as its work lives: an ID, resources, or both.

The part around the work that every entry point shares: the runner's attempts (the
test runs in a child) and the pytest plugin (its tests run in its own process) both
hold through :func:`isolation`, so reservation, the end of what the work left behind,
the blocks and the release are one code path.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from ros_isolated_test.domain_coordinator.reservation import (
    DomainCoordinator,
    Reservation,
    ResourceHold,
)
from ros_isolated_test.process import reaper, sweep

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from pathlib import Path

    from ros_isolated_test.process import proc
    from ros_isolated_test.runner import environment, settings


class Lease:
    """What the work holds while it runs: its ID and resources, the wait for them, its survivors.

    Not a record in the lock directory (``records``, ``resource_holds.Hold``) nor what
    releases it (``Reservation``, ``ResourceHold``): the run's own view of what it holds.
    """

    __slots__ = ("domain_id", "reserved", "resources", "survivors", "waited", "waited_resources")

    def __init__(
        self,
        domain_id: int | None,
        resources: dict[str, int] | None = None,
        waited: float = 0.0,
        waited_resources: float = 0.0,
        reserved: bool = True,
    ) -> None:
        #: None only for resources held with isolation disabled.
        self.domain_id = domain_id
        #: False for a test in namespaces of its own that found no ID free: it runs on
        #: ``domain_id`` without holding it (its namespaces keep it apart).
        self.reserved = reserved
        #: The machine resources held with it ({} for none), how long the wait was, and
        #: how much of it the resources were short (the rest: no ID).
        self.resources = resources or {}
        self.waited = waited
        self.waited_resources = waited_resources
        #: The supervisor's survivors once it returned: the authoritative list, the one
        #: the result names. None until then: a run that ended otherwise scans afresh.
        self.survivors: Sequence[proc.Stat] | None = None


def leftover_note(leftover: str) -> str:
    """The line naming a process the work left running, ended by the sweep."""
    return f"stopped process {leftover}, left running by the test"


@contextlib.contextmanager
def isolation(
    policy: environment.Policy,
    config: settings.Settings,
    command: Sequence[str],
    note: Callable[[str], None],
    sweep_grace: float | None = None,
) -> Iterator[Lease | None]:
    """Hold a domain ID for the ``with`` block (a :class:`Lease`; None: no isolation), then release.

    With ``sweep_grace`` (work that ran in this process, the pytest plugin) this process
    adopts orphans for the block, and after it the supervisor's sweep ends every process
    the work left in its tree (SIGTERM, ``sweep_grace`` seconds, then SIGKILL), naming
    each; processes that were children before the block are not the work's, and stay.
    Either way, what survives keeps the ID blocked, and only then is the ID released.
    The resources ``config`` asks for are held with the ID, and without one when
    isolation is disabled (a GPU is as scarce either way); survivors keep them held too.
    In namespace mode no ID is waited for (one free is held, else the pool's first is
    used unreserved: ``held.reserved``); resources are waited for as ever. Work in this
    very process enters the namespaces here, once the reservation has looked at the
    host's network (ports, participants). Raises PoolExhaustedError or LockDirError when
    no ID can be had, CapacityConflictError when runners disagree, NamespaceError when
    this process cannot enter its namespaces.
    """
    if not policy.isolate and not config.resources:
        yield None
        return
    others: frozenset[tuple[int, int]] = frozenset()
    adopted = False
    if sweep_grace is not None:
        # Ours for the block only: an embedding program is given back as it was.
        adopted = not reaper.is_subreaper() and reaper.become_subreaper()
        others = sweep.existing_children()
    try:
        held, taken = _take(policy, config, command, note)
        try:
            if policy.namespaces and sweep_grace is not None:
                from ros_isolated_test.process import namespace

                namespace.enter_here()
            yield held
        finally:
            try:
                if sweep_grace is not None:
                    # The supervisor's own sweep, as after a test it ran: one way to end a tree.
                    leftovers, held.survivors = sweep.end_leftovers(sweep_grace, others)
                    for leftover in leftovers:
                        note(leftover_note(leftover))
                _block_survivors(taken, held, note)
            finally:
                taken.release()
    finally:
        if adopted:
            reaper.stop_subreaper()


class _Taken:
    """What a run holds: an ID, resources, or (namespace mode) each apart; let go together."""

    __slots__ = ("parts",)

    def __init__(self, *parts: Reservation | ResourceHold) -> None:
        self.parts = list(parts)

    def block_for(self, processes: Sequence[proc.Stat]) -> Path | None:
        """Keep every part held while ``processes`` live; the first record (None: nothing held)."""
        records = [part.block_for(processes) for part in self.parts]
        return records[0] if records else None

    def release(self) -> None:
        for part in reversed(self.parts):
            part.release()


def _take(
    policy: environment.Policy,
    config: settings.Settings,
    command: Sequence[str],
    note: Callable[[str], None],
) -> tuple[Lease, _Taken]:
    """Reserve what the run needs: an ID (waiting, unless in namespaces), the resources."""
    coordinator = DomainCoordinator(config.lock_dir, config.pool, config.resources, config.capacity)
    if not policy.isolate:
        hold = coordinator.hold_resources(command, config.wait_timeout, note)
        return Lease(None, config.resources, hold.waited, hold.waited_resources), _Taken(hold)
    if not policy.namespaces:
        taken = coordinator.acquire(command, config.wait_timeout, note)
        held = Lease(taken.domain_id, config.resources, taken.waited, taken.waited_resources)
        return held, _Taken(taken)
    parts = _Taken()
    waited = (0.0, 0.0)
    try:
        if config.resources:
            hold = coordinator.hold_resources(command, config.wait_timeout, note)
            parts.parts.append(hold)
            waited = (hold.waited, hold.waited_resources)
        reservation = DomainCoordinator(config.lock_dir, config.pool).reserve_if_free(command)
    except BaseException:
        parts.release()
        raise
    if reservation is None:
        # Any ID will do in a network of its own: the pool's first, said to be shared.
        return Lease(config.pool[0], config.resources, *waited, reserved=False), parts
    parts.parts.append(reservation)
    return Lease(reservation.domain_id, config.resources, *waited), parts


def _block_survivors(taken: _Taken, held: Lease, note: Callable[[str], None]) -> None:
    """What of the work's tree still lives keeps the ID and the resources until it is gone.

    Not ours to kill, or stuck in the kernel. The supervisor's own list when it returned
    (never a process of an embedding program); a scan of our tree only when it did not
    (an error in the runner).
    """
    survivors = held.survivors
    if survivors is None:
        survivors = sweep.survivors()
    if not survivors:
        return
    from ros_isolated_test.domain_coordinator.resources import describe

    if not taken.parts:
        return  # nothing held (namespace mode, no ID free): named above, nothing to keep
    names = ", ".join(survivor.describe() for survivor in survivors)
    own_id = held.domain_id is not None and held.reserved
    kept = [f"ROS_DOMAIN_ID {held.domain_id}"] if own_id else []
    kept += [describe(held.resources)] if held.resources else []
    what = " and ".join(kept)
    try:
        record = taken.block_for(survivors)
    except OSError as error:
        note(
            f"cannot keep {what} blocked while {names} live: {error}; make the lock "
            "directory writable"
        )
    else:
        verb = "stays" if len(kept) == 1 else "stay"
        where = "" if record is None else f" ({record.name})"
        note(f"{what} {verb} blocked while {names} live{where}; see ros-isolated-test status")
