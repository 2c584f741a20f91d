"""``flock``: the coordinator's lock, filelock's own, taken without filelock.

``try_lock`` takes a free lock and says False for one another open file holds, raising
only for a descriptor flock cannot lock at all. The blocking lock (``wait_lock``) is one
call that sleeps in the kernel, never a poll: a waiter is woken only when the lock is
let go: while it waits, its voluntary context switches (``/proc/PID/status``) stay where
they were, where a poller (what filelock's ``lock_descriptor`` does: a non-blocking try
every 50 ms) gains one per try; that poller is the control. The lock is still filelock's
own (an exclusive ``flock`` of the whole file, as ``FileLock`` takes it on every version,
Ubuntu 24.04's 3.13.1 too), and a runner that queues for an ID never imports filelock.
"""

from __future__ import annotations

import errno
import fcntl
import os
import subprocess
import sys
from pathlib import Path

import filelock
import pytest
from helpers.commands import CLI, HUNG
from helpers.coordinator import FLOCK_SCRIPT, hold_the_pool
from helpers.processes import Children, poll_until

from ros_isolated_test.domain_coordinator.flock import try_lock, wait_lock
from ros_isolated_test.process import proc

#: A child that opens argv[1], says so, then waits for its lock: blocking, or polling.
WAITER = """
import os, sys, time
from ros_isolated_test.domain_coordinator.flock import try_lock, wait_lock
fd = os.open(sys.argv[1], os.O_RDWR)
print("waiting", flush=True)
if sys.argv[2] == "block":
    wait_lock(fd)
else:  # the control: what lock_descriptor did
    while not try_lock(fd):
        time.sleep(0.05)
print("locked", flush=True)
sys.stdin.read()
"""


def _switches(pid: int) -> int:
    """The process's voluntary context switches: one each time it went to sleep."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("voluntary_ctxt_switches:"):
            return int(line.split()[1])
    raise AssertionError(f"no voluntary_ctxt_switches for {pid}")


def _sleeping(pid: int) -> bool:
    stat = proc.read_stat(pid)
    return stat is not None and stat.state == "S"


def _held(path: Path) -> int:
    """``path`` created and locked by this process; the descriptor."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX)
    return fd


# -- one try -------------------------------------------------------------------------------


def test_one_try_takes_a_free_lock_and_not_one_another_process_holds(
    children: Children, tmp_path: Path
) -> None:
    path = tmp_path / "domain-7.lock"
    holder = children.python(FLOCK_SCRIPT, path)
    assert children.first_line(holder) == "locked"
    fd = os.open(path, os.O_RDONLY)
    try:
        assert try_lock(fd) is False
        children.finish(holder)
        assert try_lock(fd) is True  # the control: the same file, let go
        # Held now by this descriptor: another open file of it, even ours, is refused.
        other = os.open(path, os.O_RDONLY)
        try:
            assert try_lock(other) is False
        finally:
            os.close(other)
    finally:
        os.close(fd)


def test_a_descriptor_flock_cannot_lock_raises_rather_than_counting_as_busy(
    tmp_path: Path,
) -> None:
    """Contention is False; anything else (here a closed descriptor) is the caller's error."""
    fd = os.open(tmp_path / "lock", os.O_RDONLY | os.O_CREAT, 0o644)
    os.close(fd)
    for attempt in (try_lock, wait_lock):
        with pytest.raises(OSError) as raised:
            attempt(fd)
        assert raised.value.errno == errno.EBADF
    # The control: an open descriptor of the same file locks both ways.
    fd = os.open(tmp_path / "lock", os.O_RDONLY)
    try:
        assert try_lock(fd) is True
        wait_lock(fd)
    finally:
        os.close(fd)


# -- the blocking lock ---------------------------------------------------------------------


def test_a_waiter_sleeps_in_one_flock_until_the_lock_is_let_go(
    children: Children, tmp_path: Path
) -> None:
    blocked_fd, polled_fd = _held(tmp_path / "blocked.lock"), _held(tmp_path / "polled.lock")
    blocked = children.python(WAITER, tmp_path / "blocked.lock", "block")
    poller = children.python(WAITER, tmp_path / "polled.lock", "poll")
    assert children.first_line(blocked) == "waiting"
    assert children.first_line(poller) == "waiting"
    poll_until(lambda: _sleeping(blocked.pid), "the waiter went to sleep")
    before = _switches(blocked.pid)
    polls = _switches(poller.pid)
    # The control shows time passing: five polls of the other waiter, each a wake-up.
    poll_until(lambda: _switches(poller.pid) >= polls + 5, "the poller polled five times")
    assert _switches(blocked.pid) == before, "the waiter was woken while the lock was held"
    assert blocked.poll() is None and _sleeping(blocked.pid)
    os.close(blocked_fd)  # let go: the kernel hands the lock to the waiter
    assert children.first_line(blocked) == "locked"
    os.close(polled_fd)
    assert children.first_line(poller) == "locked"


def test_a_filelock_and_a_waiter_exclude_each_other(children: Children, tmp_path: Path) -> None:
    """The lock is filelock's: a FileLock holder keeps a waiter out, and the reverse."""
    path = tmp_path / "shared.lock"
    path.touch()
    holder = filelock.FileLock(str(path), timeout=0)
    holder.acquire()
    waiter = children.python(WAITER, path, "block")
    assert children.first_line(waiter) == "waiting"
    poll_until(lambda: _sleeping(waiter.pid), "the waiter went to sleep")
    holder.release()
    assert children.first_line(waiter) == "locked"
    with pytest.raises(filelock.Timeout):
        filelock.FileLock(str(path), timeout=0).acquire()
    children.finish(waiter)
    with filelock.FileLock(str(path), timeout=0):
        pass  # the waiter gone, its lock went with it


def _imported(stderr: str) -> set[str]:
    """The modules ``python -X importtime`` reported, by their full names."""
    return {
        line.rsplit("|", 1)[1].strip()
        for line in stderr.splitlines()
        if line.startswith("import time:") and "|" in line
    }


def test_a_runner_that_queues_for_an_id_never_imports_filelock(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    go = hold_the_pool(one_id, tmp_path, started)
    lock_dir = Path(one_id["ROS_ISOLATED_TEST_LOCK_DIR"])
    waiter = subprocess.Popen(
        [sys.executable, "-X", "importtime", CLI, "run", "--", "true"],
        env=one_id,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    started.append(waiter)  # type: ignore[arg-type]
    poll_until(lambda: any(lock_dir.glob("queue*/*.ticket")), "the waiter took a ticket")
    go.touch()
    stdout, stderr = waiter.communicate(timeout=HUNG)
    assert waiter.returncode == 0, stdout + stderr
    assert "waiting for a free ROS_DOMAIN_ID" in stderr + stdout
    names = _imported(stderr)
    assert "ros_isolated_test.domain_coordinator.queue" in names, "the check must see the wait"
    assert not [name for name in names if name.split(".")[0] == "filelock"], sorted(names)
