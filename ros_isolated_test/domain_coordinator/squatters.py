"""Processes that use a domain ID without holding it: escaped tests, a shell's export.

A test process can outlive its runner (a runner killed with SIGKILL from outside ctest)
or a ROS process can be started by other tools with ROS_DOMAIN_ID set. Either one
still talks on that domain, so the coordinator does not hand the ID out while any live
process it can inspect carries ``ROS_DOMAIN_ID=<id>`` in its environment.
"""

from __future__ import annotations

import contextlib
import os
import pwd
import re
import time

_VARIABLE = b"ROS_DOMAIN_ID="
#: Compiled on first use (re's cache): most scans find no variable to read.
_LEADING_NUMBER = r"\s*(0[xX][0-9a-fA-F]+|[0-9]+)"


class Squatter:
    """A live process with ROS_DOMAIN_ID in its environment."""

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
        try:
            with open(f"/proc/{current}/stat", "rb") as handle:
                data = handle.read()
            current = int(data[data.rfind(b")") + 2 :].split()[1])
        except (OSError, ValueError, IndexError):
            break
        if current <= 1 or current in found:
            break
        found.add(current)
    return found


def _boot_time() -> float:
    with contextlib.suppress(OSError, ValueError), open("/proc/stat", "rb") as handle:
        for line in handle:
            if line.startswith(b"btime "):
                return float(line.split()[1])
    return 0.0


def scan(domains: set[int] | None = None) -> dict[int, list[Squatter]]:
    """Every inspectable live process using a domain (of ``domains``, if given).

    One pass over /proc; environments of other users' processes are unreadable
    unless we are root, and are skipped.
    """
    found: dict[int, list[Squatter]] = {}
    me = str(os.getpid())
    try:
        entries = [name for name in os.listdir("/proc") if name.isdigit() and name != me]
    except OSError:
        return found
    boot: float | None = None
    ticks = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    for name in entries:
        environ = _environ(name)
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
            boot = _boot_time()
        found.setdefault(domain, []).append(_describe(name, domain, boot, ticks))
    return found


def _environ(pid: str) -> bytes:
    """A process's environment block; empty when it is gone or not ours to read.

    Bare descriptors, no file objects: this runs for every process on the machine,
    once per reservation.
    """
    try:
        fd = os.open(f"/proc/{pid}/environ", os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return b""
    try:
        chunks: list[bytes] = []
        while chunk := os.read(fd, 65536):
            chunks.append(chunk)
    except OSError:
        return b""
    finally:
        os.close(fd)
    return b"".join(chunks)


def _describe(pid: str, domain: int, boot: float, ticks: int) -> Squatter:
    user, command, started = "?", "?", 0.0
    with contextlib.suppress(OSError, KeyError):
        user = pwd.getpwuid(os.stat(f"/proc/{pid}").st_uid).pw_name
    with contextlib.suppress(OSError):
        with open(f"/proc/{pid}/cmdline", "rb") as handle:
            raw = handle.read().rstrip(b"\0")
        command = raw.replace(b"\0", b" ").decode("utf-8", "replace") or "?"
    with contextlib.suppress(OSError, ValueError, IndexError):
        with open(f"/proc/{pid}/stat", "rb") as handle:
            data = handle.read()
        fields = data[data.rfind(b")") + 2 :].split()
        started = boot + int(fields[19]) / ticks
    return Squatter(int(pid), domain, user, command, started or time.time())
