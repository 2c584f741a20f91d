"""Waiting for a domain ID (and resources): the queue's policy, apart from the taking.

A runner that finds nothing free waits in line, first come, first served: it takes a
ticket (``queue``), tries only when its turn has come (with resources: under the mutex,
in the order ``resource_holds`` keeps), looks again on a schedule, says every 10 s why it
waits, and gives up with a message naming who holds what. What one try takes (an ID,
resources, or both) is the reservation's business: ``reservation`` hands it in as
``take``, so the policy can be read (and changed) without the locks and records.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

from ros_isolated_test import not_run
from ros_isolated_test.domain_coordinator.lock_dir import ensure_lock_dir
from ros_isolated_test.domain_coordinator.queue import RESOURCE_MARK, Queue
from ros_isolated_test.domain_coordinator.resources import describe

#: How often a waiting runner first in line tries for an ID, and how often the others look.
HEAD_POLL_SECONDS = 0.05
QUEUE_POLL_SECONDS = 0.1

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from typing import Protocol, TypeVar

    class Taken(Protocol):
        """What a wait ends with (a reservation, or resources held): it learns how long."""

        waited: float
        waited_resources: float

    TakenT = TypeVar("TakenT", bound=Taken)


class PoolExhaustedError(not_run.NotRun, RuntimeError):
    """No ID became free in time; the message says who holds them and what to do."""

    reason = not_run.BUSY


class ResourcesBusyError(PoolExhaustedError):
    """The resources asked for did not come free in time (exit code as for no ID)."""


class Waiting:
    """One request's wait in line: the pool and resources asked for, and why it waits."""

    def __init__(
        self,
        lock_dir: Path,
        pool: tuple[int, ...],
        resources: dict[str, int],
        capacity: dict[str, int],
    ) -> None:
        self.lock_dir = lock_dir
        self.pool = pool
        self.resources = resources
        self.capacity = capacity
        #: Why the last attempt got nothing, when resources were the reason (for messages).
        self.short: str | None = None

    def wait(
        self,
        command: Sequence[str],
        wait_timeout: float,
        on_wait: Callable[[str], None] | None,
        domain: bool,
        take: Callable[[bool], TakenT | None],
    ) -> TakenT:
        """Take what is asked (``take(domain)``) in turn, waiting first come, first served."""
        # Refused before anything is read or written through a planted path (the queue).
        ensure_lock_dir(self.lock_dir)
        queue = Queue(self.lock_dir)
        start = time.monotonic()
        # Not waiting at all: any free ID will do. Otherwise behind every earlier waiter
        # (no ticket yet: behind them all), unless nobody waits.
        before = "" if wait_timeout <= 0 or not queue.waiting() else None
        taken, _turn = self.attempt(queue, before, domain, take)
        if taken is not None:
            return taken
        if wait_timeout <= 0:
            raise self.gave_up("", 0.0)
        told = 0.0
        # Of the wait, the time the resources asked for were short (a runner that has no
        # ID waits for an ID otherwise): each pause counts as the try before it found.
        short = 0.0
        was_short, mark = self.short is not None, start
        extra = ""
        if self.resources:
            from ros_isolated_test.domain_coordinator import resource_holds

            extra = resource_holds.ticket_fields(self.resources, self.capacity, domain)
        with queue.ticket(command, extra, marked=bool(self.resources)) as ticket:
            if queue.problem is not None and on_wait is not None:
                on_wait(queue.problem)  # once: the planted path, and what we do instead
            while True:
                waited = time.monotonic() - start
                # Without a ticket (none could be made) a runner waits out of order.
                name = ticket.name if ticket is not None else ""
                taken, turn = self.attempt(queue, name, domain, take)
                now = time.monotonic()
                if was_short:
                    short += now - mark
                was_short, mark = self.short is not None, now
                if taken is not None:
                    taken.waited = now - start
                    # Without an ID, all of the wait was for the resources.
                    taken.waited_resources = min(short, taken.waited) if domain else taken.waited
                    return taken
                if waited >= wait_timeout:
                    raise self.gave_up("waited", waited)
                if on_wait is not None and (told == 0.0 or waited - told >= 10.0):
                    told = waited or 0.001
                    ahead = ticket.ahead() if ticket is not None else 0
                    on_wait(self.waiting_message(ahead, waited, wait_timeout))
                # A runner whose turn it is looks often (an attempt is a few lock calls);
                # the rest only need to notice when their turn comes.
                time.sleep(HEAD_POLL_SECONDS if turn else QUEUE_POLL_SECONDS)

    def attempt(
        self,
        queue: Queue,
        before: str | None,
        domain: bool,
        take: Callable[[bool], TakenT | None],
    ) -> tuple[TakenT | None, bool]:
        """One try, in turn: (what was taken or None, whether it was our turn to try).

        ``before``: our ticket's name; None for a newcomer behind every waiter; "" to
        take whatever is free regardless of waiters.
        """
        self.short = None
        if not self.resources:
            if before != "" and self.id_ahead(queue, before):
                return None, False
            return take(domain), True
        from ros_isolated_test.domain_coordinator import resource_holds

        with resource_holds.mutex(self.lock_dir) as held:
            if not held:
                return None, True  # someone is deciding: look again soon
            board = resource_holds.picture(
                self.lock_dir, queue, self.resources, self.capacity, before
            )
            mine = resource_holds.Demand(before or "", self.resources, domain)
            fits, turn = board.may_go(mine, before)
            if not fits:
                self.short = board.shortage(self.resources)
                return None, False
            if not turn:
                return None, False
            return take(domain), True

    def id_ahead(self, queue: Queue, before: str | None) -> bool:
        """Whether an earlier waiter is to get an ID first (so an ID-only runner waits).

        Tickets that ask for resources count only while what they ask for is free: a
        waiter held up by a GPU holds up nobody who asks for an ID alone. Their records
        are read only when such tickets exist.
        """
        earlier = [
            path.name for path in queue.live_tickets() if before is None or path.name < before
        ]
        if not earlier:
            return False
        if not any(name.endswith(RESOURCE_MARK + ".ticket") for name in earlier):
            return True
        from ros_isolated_test.domain_coordinator import resource_holds

        board = resource_holds.picture(self.lock_dir, queue, {}, {})
        _fits, turn = board.may_go(resource_holds.Demand(before or "~", {}, True), before)
        return not turn

    def waiting_message(self, ahead: int, waited: float, limit: float) -> str:
        """Why the runner still waits: the resources short, or who holds the pool."""
        if self.short is not None:
            return (
                f"waiting for {describe(self.resources)} ({waited:.1f} s of {limit:g} s, "
                f"{ahead} runner(s) ahead): {self.short}"
            )
        from ros_isolated_test.domain_coordinator.status import pool_usage

        held, holders = pool_usage(self.lock_dir, self.pool)
        if held < len(self.pool):
            # Free IDs, but an earlier waiter takes the next one first (first come, first served).
            why = f"{len(self.pool) - held} of {len(self.pool)} IDs free, for earlier waiters first"
        else:
            why = f"all {len(self.pool)} IDs of the pool are in use"
        return (
            f"waiting for a free ROS_DOMAIN_ID ({waited:.1f} s of {limit:g} s, "
            f"{ahead} runner(s) ahead): {why}: {holders}"
        )

    def gave_up(self, how: str, waited: float) -> PoolExhaustedError:
        """The error for a runner that got nothing: resources or the pool."""
        if self.short is not None:
            spent = f"after waiting {waited:.0f} s, " if how else ""
            return ResourcesBusyError(
                f"{spent}{describe(self.resources)} is not free: {self.short} (see "
                "ros-isolated-test status); run fewer tests at once, ask for less, or wait "
                "longer with --wait-timeout / ROS_ISOLATED_TEST_WAIT_TIMEOUT"
            )
        return PoolExhaustedError(self._exhausted(how, waited))

    def _exhausted(self, how: str, waited: float) -> str:
        from ros_isolated_test.domain_coordinator.status import describe_holders

        spent = f"after waiting {waited:.0f} s, " if how else ""
        return (
            f"{spent}no free ROS_DOMAIN_ID: all {len(self.pool)} IDs of the pool are in use "
            f"({describe_holders(self.lock_dir, self.pool)}; see ros-isolated-test status); "
            "run fewer tests at once (ctest -j), widen the pool with "
            "ROS_ISOLATED_TEST_DOMAINS (e.g. '1-101,215-232'), or wait longer with "
            "--wait-timeout / ROS_ISOLATED_TEST_WAIT_TIMEOUT"
        )
