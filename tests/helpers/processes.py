"""Child processes of a test: started, read, told to finish through stdin, always killed.

Tests that hold IDs in other processes (holders, waiters, other users' runners) use one
``Children`` each (the ``children`` fixture), so nothing a test started outlives it.
"""

from __future__ import annotations

import os
import pwd
import select
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypedDict

import pytest

from ros_isolated_test.process import proc

#: Only stops a hung test: how long to wait for a child that should answer at once.
DEADLINE = 60.0

#: A test command: writes its PID, then waits for a file or its deadline. argv: pid file, go.
WAIT_SCRIPT = """
import os, sys, time
from pathlib import Path
Path(sys.argv[1]).write_text(str(os.getpid()))
deadline = time.monotonic() + 60
while not Path(sys.argv[2]).exists() and time.monotonic() < deadline:
    time.sleep(0.02)
"""


class Children:
    """Child processes of one test, each controlled through its stdin; all killed at the end."""

    def __init__(self) -> None:
        self.processes: list[subprocess.Popen[str]] = []

    def start(self, args: Sequence[str], **kwargs: object) -> subprocess.Popen[str]:
        process: subprocess.Popen[str] = subprocess.Popen(  # type: ignore[call-overload]
            list(args),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            **kwargs,
        )
        self.processes.append(process)
        return process

    def python(self, script: str, *args: object, **kwargs: object) -> subprocess.Popen[str]:
        return self.start([sys.executable, "-c", script, *map(str, args)], **kwargs)

    def first_line(self, process: subprocess.Popen[str]) -> str:
        """The child's next line of output, or a failure showing why it never came.

        Read from the descriptor a byte at a time: a buffered ``readline`` may take the
        lines after it too, and a ``select`` on the descriptor then waits for output
        that was already read (the next call would fail although its line had come).
        """
        assert process.stdout is not None
        fd = process.stdout.fileno()
        data = b""
        deadline = time.monotonic() + DEADLINE
        while not data.endswith(b"\n"):
            ready, _, _ = select.select([fd], [], [], max(deadline - time.monotonic(), 0.0))
            byte = os.read(fd, 1) if ready else b""
            if not byte:
                break  # the deadline, or the end of its output
            data += byte
        line = data.decode("utf-8", "replace")
        if not line:
            process.kill()
            _, stderr = process.communicate(timeout=DEADLINE)
            pytest.fail(f"child {process.args!r} printed nothing; stderr:\n{stderr}")
        return line.strip()

    def finish(self, process: subprocess.Popen[str]) -> int:
        """Close its stdin (the signal to let go) and wait for it."""
        assert process.stdin is not None
        process.stdin.close()
        return process.wait(timeout=DEADLINE)

    def kill_all(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.kill()
            process.wait(timeout=DEADLINE)
            for stream in (process.stdin, process.stdout, process.stderr):
                if stream is not None:
                    stream.close()


def wait_for(path: Path, timeout: float = DEADLINE) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        if time.monotonic() > deadline:
            pytest.fail(f"{path} did not appear within {timeout} s")
        time.sleep(0.02)


def stat_of(pid: int) -> proc.Stat:
    """A live process as survivors are named (PID and start time): it must be running."""
    found = proc.read_stat(pid)
    assert found is not None, f"process {pid} is gone"
    return found


def carrying(entry: str) -> list[int]:
    """Live processes whose environment holds ``entry`` (``NAME=value``), found whatever
    their names: how a test finds every process of a session it marked (zombies are dead)."""
    wanted = entry.encode()
    found = []
    for pid in proc.pids():
        stat = proc.read_stat(pid)
        if stat is not None and stat.alive and wanted in proc.environ(pid).split(b"\0"):
            found.append(int(pid))
    return found


def poll_until(condition: Callable[[], bool], what: str, timeout: float = DEADLINE) -> None:
    """Wait until ``condition()`` holds; fail naming ``what`` after ``timeout`` (a hang stopper)."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting: {what}")
        time.sleep(0.05)


class UserKeywords(TypedDict):
    """What ``subprocess`` needs to run a child as another user."""

    user: int
    group: int
    extra_groups: list[int]
    cwd: str


def user_keywords(uid: int) -> UserKeywords:
    """``subprocess`` keywords that run a child as user ``uid``, in its own group only."""
    entry = pwd.getpwuid(uid)
    return {"user": uid, "group": entry.pw_gid, "extra_groups": [], "cwd": "/"}
