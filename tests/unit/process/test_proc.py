"""The one /proc reader (``process.proc``) against real processes.

Every other module (the supervisor's tree walk, the squatter scan, block records)
trusts what it parses: a wrong field here is a wrong PID signalled or a survivor missed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.process_tree import AWKWARD_NAME, awkward_sleeper
from helpers.processes import DEADLINE, poll_until

from ros_isolated_test.process import proc

#: A user ID nobody has here, for a process that is not ours.
OTHER_UID = 4242


@pytest.fixture
def sleeper(tmp_path: Path) -> Iterator[subprocess.Popen[bytes]]:
    """A child whose executable (so whose kernel name) is :data:`AWKWARD_NAME`."""
    with awkward_sleeper(tmp_path) as child:
        yield child


def test_stat_of_a_name_with_spaces_and_parentheses(
    sleeper: subprocess.Popen[bytes],
) -> None:
    stat = proc.read_stat(sleeper.pid)
    assert stat is not None
    assert stat.name == AWKWARD_NAME
    assert (stat.pid, stat.ppid, stat.pgid) == (sleeper.pid, os.getpid(), os.getpgrp())
    assert stat.alive
    me = proc.read_stat(os.getpid())
    assert me is not None
    # Started after us: its start tick is not before ours (ticks, not wall-clock).
    assert stat.start >= me.start
    assert stat.describe() == f"{sleeper.pid} ({AWKWARD_NAME})"


def test_the_state_follows_stop_continue_and_exit(sleeper: subprocess.Popen[bytes]) -> None:
    def state() -> str:
        stat = proc.read_stat(sleeper.pid)
        assert stat is not None
        return stat.state

    poll_until(lambda: state() == "S", "sleep to sleep")
    os.kill(sleeper.pid, signal.SIGSTOP)
    poll_until(lambda: state() in proc.STOPPED_STATES, "the stop")
    os.kill(sleeper.pid, signal.SIGCONT)
    poll_until(lambda: state() not in proc.STOPPED_STATES, "the continue")
    stat = proc.read_stat(sleeper.pid)
    assert stat is not None
    assert _key(proc.living(sleeper.pid, stat.start)) == stat.key
    os.kill(sleeper.pid, signal.SIGKILL)
    # Not reaped yet: a zombie, which runs no more and so is no survivor.
    poll_until(lambda: state() == "Z", "the zombie")
    zombie = proc.read_stat(sleeper.pid)
    assert zombie is not None and not zombie.alive
    assert proc.living(sleeper.pid, stat.start) is None
    sleeper.wait(DEADLINE)
    assert proc.read_stat(sleeper.pid) is None
    assert proc.living(sleeper.pid, stat.start) is None


def test_a_pid_with_another_start_time_is_another_process(
    sleeper: subprocess.Popen[bytes],
) -> None:
    """What a recycled PID looks like: same number, later start."""
    stat = proc.read_stat(sleeper.pid)
    assert stat is not None
    assert _key(proc.living(sleeper.pid, stat.start)) == stat.key
    assert proc.living(sleeper.pid, stat.start - 1) is None
    assert proc.living(sleeper.pid, stat.start + 1) is None


def _key(stat: proc.Stat | None) -> tuple[int, int] | None:
    return None if stat is None else stat.key


def test_environ_cmdline_and_pids(sleeper: subprocess.Popen[bytes], tmp_path: Path) -> None:
    assert proc.environ(sleeper.pid).split(b"\0")[:2] == [b"MARKER=one two", b"X=y"]
    assert proc.cmdline(sleeper.pid) == f"{tmp_path / AWKWARD_NAME} 600 0"
    # Its arguments one by one (a space inside one stays in it), and what it loaded.
    assert proc.argv(sleeper.pid) == [str(tmp_path / AWKWARD_NAME), "600", "0"]
    assert b"libc" in proc.maps(sleeper.pid)
    found = proc.pids()
    assert str(sleeper.pid) in found and str(os.getpid()) in found
    assert all(name.isdigit() for name in found)


def test_gone_processes_read_as_empty() -> None:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait(DEADLINE)
    assert proc.read_stat(child.pid) is None
    assert proc.environ(child.pid) == b""
    assert proc.cmdline(child.pid) == ""
    assert proc.argv(child.pid) == [] and proc.maps(child.pid) == b""
    assert proc.owner_uid(child.pid) is None


@capabilities.ROOT
def test_the_owner_is_the_user_the_process_runs_as() -> None:
    """Read from /proc, not assumed to be us: a child running as another user."""
    # Popen returns once the child has exec'd, so after its change of user.
    child = subprocess.Popen(["sleep", "600"], user=OTHER_UID)
    try:
        assert proc.owner_uid(child.pid) == OTHER_UID
        assert proc.owner_uid(os.getpid()) == os.getuid()  # the control
    finally:
        child.kill()
        child.wait(DEADLINE)


def test_pid_max_is_the_kernels_and_bounds_every_pid() -> None:
    kernel = int(Path("/proc/sys/kernel/pid_max").read_text())
    assert proc.pid_max() == min(kernel, proc.PID_MAX_LIMIT)
    assert 1 < os.getpid() < proc.pid_max()


def test_started_at_is_when_the_process_started() -> None:
    before = time.time()
    child = subprocess.Popen(["sleep", "600"])
    try:
        stat = proc.read_stat(child.pid)
        assert stat is not None
        started = proc.started_at(stat)
    finally:
        child.kill()
        child.wait(DEADLINE)
    # btime is whole seconds and ticks are 1/100 s: within a second or two of the truth.
    assert before - 2 <= started <= time.time() + 2


@pytest.mark.parametrize(
    "line",
    [b"", b"12 (name", b"12 name) S 1", b"12 (x) S 1 2 3", b"12 (x) S one 2" + b" 0" * 30],
)
def test_a_line_that_is_no_stat_line_is_refused(line: bytes) -> None:
    assert proc.parse_stat(12, line) is None


def test_identity_of_this_boot_and_namespace() -> None:
    assert len(proc.boot_id()) == 36  # a UUID
    assert proc.pid_namespace().startswith("pid:[")
    assert proc.boot_time() > 0
