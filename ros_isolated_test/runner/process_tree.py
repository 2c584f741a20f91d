"""The test's process tree, found through /proc parent links (as ctest finds it on timeout).

Signalling only the test's main process would leave its children running, on a domain
ID the coordinator is about to hand to the next test.
"""

from __future__ import annotations

import contextlib
import os


def _parents() -> dict[int, int]:
    """PID -> parent PID of every process we can see."""
    parents: dict[int, int] = {}
    with contextlib.suppress(OSError):
        for entry in os.scandir("/proc"):
            if not entry.name.isdigit():
                continue
            try:
                with open(f"/proc/{entry.name}/stat", "rb") as handle:
                    data = handle.read()
            except OSError:
                continue
            # The command name may hold spaces and parentheses: fields follow the last ')'.
            fields = data[data.rfind(b")") + 2 :].split()
            if len(fields) > 1:
                parents[int(entry.name)] = int(fields[1])
    return parents


def descendants(pid: int) -> list[int]:
    """Every living descendant of ``pid``, parents before children."""
    children: dict[int, list[int]] = {}
    for child, parent in _parents().items():
        children.setdefault(parent, []).append(child)
    found: list[int] = []
    queue = list(children.get(pid, ()))
    while queue:
        current = queue.pop(0)
        found.append(current)
        queue.extend(children.get(current, ()))
    return found


def signal_tree(pid: int, signum: int) -> None:
    """Send ``signum`` to ``pid`` and every descendant; gone processes are skipped."""
    for target in [pid, *descendants(pid)]:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(target, signum)
