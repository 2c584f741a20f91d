"""Processes that use a domain ID without holding it: escaped tests, a shell's export.

A test process can outlive its runner (a runner killed with SIGKILL from outside ctest)
or a ROS process can be started by other tools with ROS_DOMAIN_ID set. Either one
still talks on that domain, so the coordinator does not hand the ID out while any live
process it can inspect carries ``ROS_DOMAIN_ID=<id>`` in its environment.
"""

from __future__ import annotations

import contextlib
import os
import re
import time

from ros_isolated_test.domain_coordinator.records import user_name
from ros_isolated_test.process import proc

_VARIABLE = b"ROS_DOMAIN_ID="
#: Compiled on first use (re's cache): most scans find no variable to read.
_LEADING_NUMBER = r"\s*(0[xX][0-9a-fA-F]+|[0-9]+)"


class Squatter:
    """A live process with ROS_DOMAIN_ID in its environment (``user`` display-safe)."""

    __slots__ = ("command", "domain_id", "pid", "started", "user")

    def __init__(self, pid: int, domain_id: int, user: str, command: str, started: float) -> None:
        self.pid = pid
        self.domain_id = domain_id
        self.user = user
        self.command = command
        self.started = started

    def __repr__(self) -> str:
        return f"Squatter(pid={self.pid}, domain_id={self.domain_id}, command={self.command!r})"


def domain_value(text: str) -> int | None:
    """The domain ROS reads from a ROS_DOMAIN_ID value (``0x10`` is 16, ``5abc`` is 5)."""
    match = re.match(_LEADING_NUMBER, text)
    if match is None:
        return None
    number = match.group(1)
    with contextlib.suppress(ValueError):
        if number.lower().startswith("0x"):
            return int(number, 16)
        if len(number) > 1 and number.startswith("0"):
            return int(number, 8)
        return int(number, 10)
    return None


def ancestors(pid: int, limit: int = 64) -> set[int]:
    """The parent, grandparent, ... of ``pid`` (to tell a holder's own test from a squatter)."""
    found: set[int] = set()
    current = pid
    for _ in range(limit):
        stat = proc.read_stat(current)
        if stat is None:
            break
        current = stat.ppid
        if current <= 1 or current in found:
            break
        found.add(current)
    return found


def scan(domains: set[int] | None = None) -> dict[int, list[Squatter]]:
    """Every inspectable live process using a domain (of ``domains``, if given).

    One pass over /proc; environments of other users' processes are unreadable
    unless we are root, and are skipped.
    """
    found: dict[int, list[Squatter]] = {}
    me = str(os.getpid())
    boot: float | None = None
    for name in proc.pids():
        if name == me:
            continue
        environ = proc.environ(name)
        start = environ.find(_VARIABLE)
        while start > 0 and environ[start - 1] != 0:
            start = environ.find(_VARIABLE, start + 1)
        if start < 0:
            continue
        end = environ.find(b"\0", start)
        value = environ[start + len(_VARIABLE) : end if end >= 0 else None]
        domain = domain_value(value.decode("ascii", "replace"))
        if domain is None or (domains is not None and domain not in domains):
            continue
        if boot is None:
            boot = proc.boot_time()
        found.setdefault(domain, []).append(_describe(name, domain, boot))
    return found


def _describe(pid: str, domain: int, boot: float) -> Squatter:
    started = 0.0
    user = user_name(proc.owner_uid(pid))
    command = proc.cmdline(pid) or "?"
    stat = proc.read_stat(pid)
    if stat is not None:
        started = proc.started_at(stat, boot)
    return Squatter(int(pid), domain, user, command, started or time.time())
