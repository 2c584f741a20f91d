"""The test's process tree, found through /proc parent links (as ctest finds it on timeout).

Signalling only the test's main process would leave its children running, on a domain
ID the coordinator is about to hand to the next test.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Container

from ros_isolated_test.process import proc


def processes() -> list[proc.Stat]:
    """Every process we can see."""
    found: list[proc.Stat] = []
    for pid in proc.pids():
        if (process := proc.read_stat(pid)) is not None:
            found.append(process)
    return found


def descendants(
    pid: int, skip: Container[tuple[int, int]] = (), zombies: bool = False
) -> list[proc.Stat]:
    """Every living descendant of ``pid``, parents before children (zombies left out).

    Processes whose :attr:`~proc.Stat.key` is in ``skip`` are left out with their own
    descendants (what a program embedding the runner started before the test).
    ``zombies``: exited ones too, whose status their parent has yet to collect.
    """
    children: dict[int, list[proc.Stat]] = {}
    for process in processes():
        if process.key not in skip:
            children.setdefault(process.ppid, []).append(process)
    found: list[proc.Stat] = []
    queue = list(children.get(pid, ()))
    index = 0
    while index < len(queue):  # breadth first: parents before children
        current = queue[index]
        index += 1
        if current.alive or zombies:
            found.append(current)
        queue.extend(children.get(current.pid, ()))
    return found


def signal_all(targets: list[proc.Stat], signum: int) -> list[proc.Stat]:
    """Send ``signum`` to each target; the ones we may not signal (EPERM) are returned.

    Processes already gone are skipped.
    """
    refused: list[proc.Stat] = []
    for target in targets:
        try:
            os.kill(target.pid, signum)
        except ProcessLookupError:
            pass
        except PermissionError:
            refused.append(target)
    return refused


def signal_tree(pid: int, signum: int) -> None:
    """Send ``signum`` to ``pid`` and every descendant.

    The descendants are found before ``pid`` is signalled: if it dies at once, its
    children are orphans at once, out of a tree scanned after. Looked for again after,
    for any it started meanwhile.
    """
    found = descendants(pid)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.kill(pid, signum)
    known = {process.key for process in found}
    found += [process for process in descendants(pid) if process.key not in known]
    signal_all(found, signum)
