"""Reading one process out of /proc: the single parser of ``/proc/<pid>/stat`` and its kin.

The supervisor walks the test's tree with it, the coordinator scans every process's
environment with it, and a block record names survivors by PID *and* start time with
it (a PID alone may be recycled by then). Bare descriptors, no file objects: the
coordinator's scan reads every process on the machine once per reservation.
"""

from __future__ import annotations

import contextlib
import os

#: ``state`` letters of a process that runs no more (zombie, dead).
GONE_STATES = frozenset("ZXx")
#: ``state`` letters of a stopped process (SIGSTOP, a tracer): it cannot fork.
STOPPED_STATES = frozenset("Tt")
#: The kernel's ceiling for pid_max (PID_MAX_LIMIT on 64-bit), when /proc does not say.
PID_MAX_LIMIT = 1 << 22


class Stat:
    """One process as its ``/proc/<pid>/stat`` line shows it."""

    __slots__ = ("name", "pgid", "pid", "ppid", "start", "state")

    def __init__(self, pid: int, ppid: int, pgid: int, state: str, name: str, start: int) -> None:
        self.pid = pid
        self.ppid = ppid
        self.pgid = pgid
        #: One letter: R, S, D, T, t, Z, X, ...
        self.state = state
        #: The kernel's command name (at most 15 bytes; may hold spaces and parentheses).
        self.name = name
        #: Start time in clock ticks since boot: with ``pid``, names the process for good.
        self.start = start

    @property
    def key(self) -> tuple[int, int]:
        """``(pid, start)``: the same process, never a later one that got its PID."""
        return (self.pid, self.start)

    @property
    def alive(self) -> bool:
        """Not a zombie: it can still run (and talk on its domain)."""
        return self.state not in GONE_STATES

    def describe(self) -> str:
        """``1234 (name)``, as messages and result files name a process."""
        return f"{self.pid} ({self.name})"

    def __repr__(self) -> str:
        return f"Stat({self.pid}, {self.name!r}, state={self.state}, start={self.start})"


def parse_stat(pid: int, data: bytes) -> Stat | None:
    """``data`` (a stat line) as a :class:`Stat`; None when it is not one.

    The command name sits in parentheses and may itself hold spaces and ')': the
    fields that follow start after the *last* ')'.
    """
    close = data.rfind(b")")
    open_ = data.find(b"(")
    if close < 0 or open_ < 0 or open_ > close:
        return None
    fields = data[close + 2 :].split()
    # state ppid pgrp session tty_nr tpgid flags minflt cminflt majflt cmajflt utime
    # stime cutime cstime priority nice num_threads itrealvalue starttime ...
    if len(fields) < 20:
        return None
    try:
        return Stat(
            pid,
            int(fields[1]),
            int(fields[2]),
            fields[0].decode("ascii", "replace"),
            data[open_ + 1 : close].decode("utf-8", "replace"),
            int(fields[19]),
        )
    except ValueError:
        return None


def read_stat(pid: int | str) -> Stat | None:
    """The process's stat; None when it is gone (or never was)."""
    # One read: the line is a few hundred bytes, and a scan reads every process's.
    data = _read(f"/proc/{pid}/stat", 4096, once=True)
    return parse_stat(int(pid), data) if data else None


def living(pid: int, start: int) -> Stat | None:
    """The process ``pid`` that started at ``start``, while it still runs (not a zombie).

    None when it is gone, a zombie, or its PID now names a later process.
    """
    found = read_stat(pid)
    return found if found is not None and found.start == start and found.alive else None


def owner_uid(pid: int | str) -> int | None:
    """The user ID the process runs as (its /proc directory's owner); None when gone."""
    try:
        return os.stat(f"/proc/{pid}").st_uid
    except OSError:
        return None


def pid_max() -> int:
    """The kernel's pid_max: every real PID is below it."""
    try:
        return min(int(_read("/proc/sys/kernel/pid_max", 32, once=True)), PID_MAX_LIMIT)
    except ValueError:  # unreadable (empty) or not a number
        return PID_MAX_LIMIT


def pids() -> list[str]:
    """Every process ID we can see, as /proc names it."""
    try:
        return [name for name in os.listdir("/proc") if name.isdigit()]
    except OSError:
        return []


def environ(pid: int | str) -> bytes:
    """The environment block (NUL-separated); empty when gone or not ours to read."""
    return _read(f"/proc/{pid}/environ")


def cmdline(pid: int | str) -> str:
    """The command line, arguments joined by spaces; empty for a zombie or kernel thread."""
    raw = _read(f"/proc/{pid}/cmdline").rstrip(b"\0")
    return raw.replace(b"\0", b" ").decode("utf-8", "replace")


def argv(pid: int | str) -> list[str]:
    """The command line's arguments; empty for a zombie, a kernel thread, or one gone."""
    raw = _read(f"/proc/{pid}/cmdline").rstrip(b"\0")
    return [arg.decode("utf-8", "replace") for arg in raw.split(b"\0")] if raw else []


def maps(pid: int | str) -> bytes:
    """The process's memory map (which shared libraries it loaded); empty when unreadable."""
    return _read(f"/proc/{pid}/maps")


def boot_time() -> float:
    """When the machine booted (epoch seconds): turns start ticks into a time of day."""
    for line in _read("/proc/stat").splitlines():
        if line.startswith(b"btime "):
            with contextlib.suppress(ValueError, IndexError):
                return float(line.split()[1])
    return 0.0


def started_at(stat: Stat, boot: float | None = None) -> float:
    """The process's start as epoch seconds."""
    boot = boot_time() if boot is None else boot
    return boot + stat.start / _ticks_per_second()


def boot_id() -> str:
    """The random ID of the running boot: start ticks of another boot name other processes."""
    return _read("/proc/sys/kernel/random/boot_id").decode("ascii", "replace").strip()


def pid_namespace() -> str:
    """Our PID namespace (``pid:[4026531836]``): PIDs of another one name other processes."""
    with contextlib.suppress(OSError):
        return os.readlink("/proc/self/ns/pid")
    return ""


def _ticks_per_second() -> int:
    with contextlib.suppress(ValueError, OSError, AttributeError):
        return max(1, os.sysconf("SC_CLK_TCK"))
    return 100


def _read(path: str, size: int = 65536, once: bool = False) -> bytes:
    """A /proc file's bytes (``once``: only the first ``size``); empty when unreadable."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return b""
    try:
        if once:
            return os.read(fd, size)
        chunks: list[bytes] = []
        while chunk := os.read(fd, size):
            chunks.append(chunk)
    except OSError:
        return b""
    finally:
        os.close(fd)
    return b"".join(chunks)
