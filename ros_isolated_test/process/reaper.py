"""Keeping the test's whole process tree under the runner, and reaping what dies in it.

As a child subreaper (Linux), the runner becomes the parent of every orphan in the
test's tree: a double-forked daemon stays its descendant, where the runner's cleanup
and ctest's timeout kill both find it. Run as PID 1 of a container, it must also reap
them, or zombies pile up.
"""

from __future__ import annotations

import contextlib
import os

from ros_isolated_test import libc

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Container

_PR_SET_CHILD_SUBREAPER = 36


_PR_GET_CHILD_SUBREAPER = 37


def become_subreaper() -> bool:
    """Adopt orphaned descendants (Linux 3.4+); False where the kernel says no."""
    if os.getpid() == 1:
        return True  # PID 1 adopts every orphan of its namespace anyway.
    return _prctl(_PR_SET_CHILD_SUBREAPER, 1)


def stop_subreaper() -> bool:
    """Adopt no more orphans: an embedding program gets back the process it had."""
    return os.getpid() == 1 or _prctl(_PR_SET_CHILD_SUBREAPER, 0)


def is_subreaper() -> bool:
    """Whether this process adopts orphans already (PID 1 always does)."""
    return os.getpid() == 1 or bool(libc.prctl_get_int(_PR_GET_CHILD_SUBREAPER))


def _prctl(option: int, argument: int) -> bool:
    call = libc.prctl()
    return call is not None and call(option, argument, 0) == 0


def reap_orphans(keep: int | None = None, spare: Container[tuple[int, int]] = ()) -> int:
    """Reap every exited child except ``keep`` (the test, whose status the supervisor collects).

    Returns how many were reaped. Stops at ``keep``: its status must stay for the supervisor.
    ``spare``: children of a program embedding the runner (the pytest plugin's pytest),
    by :attr:`~proc.Stat.key`: their status stays for that program to collect, so the
    exited ones are found by name in /proc instead of taken as they come.
    """
    if spare:
        return _reap_all_but(keep, spare)
    reaped = 0
    while True:
        try:
            info = os.waitid(os.P_ALL, 0, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:
            return reaped
        if info is None or info.si_pid in (0, keep):
            return reaped
        with contextlib.suppress(ChildProcessError):
            os.waitpid(info.si_pid, 0)
            reaped += 1


def _reap_all_but(keep: int | None, spare: Container[tuple[int, int]]) -> int:
    """Reap each exited child of ours that is neither ``keep`` nor one of ``spare``."""
    from ros_isolated_test.process import tree

    me, reaped = os.getpid(), 0
    for process in tree.processes():
        if process.ppid != me or process.alive or process.pid == keep or process.key in spare:
            continue
        with contextlib.suppress(ChildProcessError):
            if os.waitpid(process.pid, os.WNOHANG)[0]:
                reaped += 1
    return reaped


def has_children() -> bool:
    """Whether any child of ours exists, exited or not: one system call, no /proc scan."""
    try:
        os.waitid(os.P_ALL, 0, os.WEXITED | os.WNOHANG | os.WNOWAIT)
    except ChildProcessError:
        return False
    return True
