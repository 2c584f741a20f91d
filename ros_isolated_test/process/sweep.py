"""The sweep of what a test left running: SIGTERM and a grace period, freeze, SIGKILL.

Apart from the supervisor because it serves more than one run: the runner's session
sweeps the pytest plugin's own tree with :func:`end_leftovers` the same way, and a run
that never got an outcome asks :func:`survivors` what is still alive before its ID goes.

When the test's main process ends, for any reason, what is left of the tree gets
SIGTERM and a grace period to exit; then the tree is frozen (SIGSTOP until no process of
it runs: a stopped process cannot fork) and SIGKILLed until it is empty. A process that
outlives even that (one we may not signal, one stuck in the kernel) is reported as a
survivor, for the caller to keep the ID blocked while it lives.
"""

from __future__ import annotations

import os
import signal
import time

from ros_isolated_test.process import proc, reaper, tree

#: How often the tree is looked at while leftovers have their grace period.
TERM_POLL_SECONDS = 0.05
#: SIGSTOP sweeps give up on processes that do not stop within this (stuck in the
#: kernel): the SIGKILL passes that follow still reach them.
FREEZE_LIMIT_SECONDS = 2.0
#: SIGKILL passes stop once the tree has not shrunk for this long: what is left cannot
#: be killed by us, and must not hang the runner.
KILL_STALL_SECONDS = 2.0
#: At most this many leftovers are named one by one (a forking daemon makes hundreds).
NAMED_LIMIT = 100


def existing_children() -> frozenset[tuple[int, int]]:
    """Processes in our tree before the test starts: a program embedding the runner's own.

    They are not the test's, and are never signalled. A runner started from a shell has
    no child yet: one system call, no /proc scan.
    """
    if not reaper.has_children():
        return frozenset()
    # Exited ones too: their status is the embedding program's to collect, never ours.
    return frozenset(process.key for process in tree.descendants(os.getpid(), zombies=True))


def survivors() -> list[proc.Stat]:
    """Living processes in this runner's tree, scanned afresh: what even SIGKILL did not end.

    Only for a run that ``supervisor.run`` never returned from (an error in the runner);
    when it returns, ``Outcome.survivors`` is the list to use, which, unlike this scan,
    leaves out what an embedding program started itself. One system call when nothing is
    left.
    """
    reaper.reap_orphans()
    if not reaper.has_children():
        return []
    return tree.descendants(os.getpid())


class _Sweep:
    """The test's tree as the final sweep sees it, pass after pass, and all it has seen."""

    def __init__(self, others: frozenset[tuple[int, int]]) -> None:
        self.me = os.getpid()
        self.others = others
        #: Every process met, by (pid, start time): the leftovers to name.
        self.seen: dict[tuple[int, int], proc.Stat] = {}

    def look(self) -> tuple[list[proc.Stat], list[proc.Stat]]:
        """Reap, then the living tree and the processes in it not met before."""
        reaper.reap_orphans(spare=self.others)
        if not reaper.has_children():
            # Every living descendant has a living child of ours above it (orphans are
            # re-parented to us, the subreaper): none at all means nothing is left.
            return [], []
        current = tree.descendants(self.me, skip=self.others)
        new = [process for process in current if process.key not in self.seen]
        for process in new:
            self.seen[process.key] = process
        return current, new

    def empty(self, current: list[proc.Stat]) -> bool:
        """Whether the tree is gone for sure, not only missing from one racy pass."""
        if current:
            return False
        reaper.reap_orphans(spare=self.others)
        return not reaper.has_children() or not _children_left(self.me, self.others)

    def terminate(self, grace: float) -> list[proc.Stat]:
        """SIGTERM every process (SIGCONT too, so a stopped one can act on it), for ``grace``.

        Processes forked meanwhile get the same. Returns what is still alive after it.
        """
        current, new = self.look()
        deadline = time.monotonic() + grace
        while True:
            tree.signal_all(new, signal.SIGTERM)
            tree.signal_all(new, signal.SIGCONT)
            remaining = deadline - time.monotonic()
            if self.empty(current) or remaining <= 0:
                return current
            time.sleep(min(TERM_POLL_SECONDS, remaining))
            current, new = self.look()

    def freeze(self) -> None:
        """SIGSTOP the tree until a pass finds none of it running.

        A stopped process cannot fork, so the SIGKILL passes that follow are no race
        against children born meanwhile. Processes we may not signal, and ones that do
        not stop within :data:`FREEZE_LIMIT_SECONDS`, are left to those passes.
        """
        refused: set[tuple[int, int]] = set()
        give_up = time.monotonic() + FREEZE_LIMIT_SECONDS
        delay = 0.001
        while True:
            current, _new = self.look()
            running = [
                process
                for process in current
                if process.state not in proc.STOPPED_STATES and process.key not in refused
            ]
            if not running or time.monotonic() >= give_up:
                return
            refused.update(process.key for process in tree.signal_all(running, signal.SIGSTOP))
            time.sleep(delay)
            delay = min(delay * 2, TERM_POLL_SECONDS)

    def kill(self) -> list[proc.Stat]:
        """SIGKILL the tree, pass after pass, reaping as it goes, until it is empty.

        Ends when :data:`KILL_STALL_SECONDS` pass without the tree shrinking: what is
        left then cannot be killed by us. Returns it.
        """
        fewest: int | None = None
        progress_at = time.monotonic()
        delay = 0.001
        while True:
            current, _new = self.look()
            if self.empty(current):
                return []
            if fewest is None or len(current) < fewest:
                fewest, progress_at = len(current), time.monotonic()
            elif time.monotonic() - progress_at >= KILL_STALL_SECONDS:
                return current
            tree.signal_all(current, signal.SIGKILL)
            time.sleep(delay)
            delay = min(delay * 2, TERM_POLL_SECONDS)


def _children_left(me: int, others: frozenset[tuple[int, int]]) -> bool:
    """Whether a child of ours, other than the embedding program's, still exists."""
    return any(process.ppid == me and process.key not in others for process in tree.processes())


def end_leftovers(
    grace: float, others: frozenset[tuple[int, int]] = frozenset()
) -> tuple[tuple[str, ...], tuple[proc.Stat, ...]]:
    """End what is left of the test's tree; name what had to be ended, and what survived.

    SIGTERM first, and ``grace`` seconds to exit cleanly (a well-behaved daemon gets its
    chance); then freeze and SIGKILL until the tree is empty, or nothing more dies.
    """
    sweep = _Sweep(others)
    remaining = sweep.terminate(grace)
    if not sweep.seen:
        return (), ()
    left: list[proc.Stat] = []
    if not sweep.empty(remaining):
        sweep.freeze()
        left = sweep.kill()
    reaper.reap_orphans(spare=others)
    alive = {process.key for process in left}
    ended = [process for key, process in sweep.seen.items() if key not in alive]
    named = [process.describe() for process in ended[:NAMED_LIMIT]]
    if len(ended) > NAMED_LIMIT:
        named.append(f"... and {len(ended) - NAMED_LIMIT} more")
    return tuple(named), tuple(left)
