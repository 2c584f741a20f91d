"""The test's process tree, found through /proc parent links (as ctest finds it on timeout).

Signalling only the test's main process would leave its children running, on a domain
ID the coordinator is about to hand to the next test.
"""

from __future__ import annotations

import contextlib
import os


class Process:
    """One process as /proc shows it."""

    __slots__ = ("name", "pgid", "pid", "ppid", "state")

    def __init__(self, pid: int, ppid: int, pgid: int, state: str, name: str) -> None:
        self.pid = pid
        self.ppid = ppid
        self.pgid = pgid
        self.state = state
        self.name = name

    def __repr__(self) -> str:
        return f"Process({self.pid}, {self.name!r}, state={self.state})"


def _read(pid: str) -> Process | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            data = handle.read()
    except OSError:
        return None
    # The command name may hold spaces and parentheses: fields follow the last ')'.
    close = data.rfind(b")")
    fields = data[close + 2 :].split()
    if len(fields) < 3:
        return None
    name = data[data.find(b"(") + 1 : close].decode("utf-8", "replace")
    return Process(int(pid), int(fields[1]), int(fields[2]), fields[0].decode(), name)


def processes() -> list[Process]:
    """Every process we can see."""
    found: list[Process] = []
    with contextlib.suppress(OSError):
        for entry in os.scandir("/proc"):
            if entry.name.isdigit() and (process := _read(entry.name)) is not None:
                found.append(process)
    return found


def descendants(pid: int, living_only: bool = True) -> list[Process]:
    """Every descendant of ``pid``, parents before children; zombies left out by default."""
    children: dict[int, list[Process]] = {}
    for process in processes():
        children.setdefault(process.ppid, []).append(process)
    found: list[Process] = []
    queue = list(children.get(pid, ()))
    while queue:
        current = queue.pop(0)
        if not living_only or current.state != "Z":
            found.append(current)
        queue.extend(children.get(current.pid, ()))
    return found


def signal_all(targets: list[Process], signum: int) -> None:
    """Send ``signum`` to each target; processes already gone are skipped."""
    for target in targets:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(target.pid, signum)


def signal_tree(pid: int, signum: int) -> None:
    """Send ``signum`` to ``pid`` and every descendant."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.kill(pid, signum)
    signal_all(descendants(pid), signum)
