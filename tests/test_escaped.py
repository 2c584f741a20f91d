"""A holder that died holding its ID: the only case where a reservation looks at /proc.

A holder's record, written when it takes an ID and removed when it releases it, is
what tells the next holder to look for processes left behind. These tests kill real
holders with SIGKILL and leave real processes on their IDs: processes between DDS
participants (no port bound, so only that look can see them), whose ID stays blocked
until they end. The controls show the same process does not block an ID whose last
holder released it cleanly: that look is skipped, which is what keeps a reservation's
cost flat on a machine with thousands of processes.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI
from helpers.domains import free_ids
from helpers.processes import DEADLINE, Children, wait_for

from ros_isolated_test.domain_coordinator import DomainCoordinator, participants
from ros_isolated_test.domain_coordinator.block import block_marker
from ros_isolated_test.domain_coordinator.escaped import died_holding
from ros_isolated_test.domain_coordinator.holder import record_path
from ros_isolated_test.domain_coordinator.reservation import release_stamp

#: Holds an ID in-process, starts a process on it (ROS_DOMAIN_ID set, stdin kept), then
#: prints both PIDs and waits to be killed. argv: lock dir, ID.
HOLD_AND_LEAVE = """
import os, subprocess, sys
from pathlib import Path
from ros_isolated_test.domain_coordinator import DomainCoordinator
reservation = DomainCoordinator(Path(sys.argv[1]), (int(sys.argv[2]),)).try_reserve(["h"])
assert reservation is not None
env = {**os.environ, "ROS_DOMAIN_ID": str(reservation.domain_id)}
left = subprocess.Popen(["sleep", "300"], env=env, start_new_session=True)
print(left.pid, flush=True)
sys.stdin.read()
"""

#: A test that was a DDS participant, closed it, and waits before opening the next one:
#: on its ID, with no port bound. Writes its PID once closed. argv: pid file, go file.
BETWEEN_PARTICIPANTS = """
import os, sys, time
from pathlib import Path
import rclpy
from rclpy.context import Context
from rclpy.signals import SignalHandlerOptions
context = Context()
rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
node = rclpy.create_node("first_participant", context=context)
node.destroy_node()
rclpy.shutdown(context=context)
Path(sys.argv[1]).write_text(str(os.getpid()))
deadline = time.monotonic() + 120
while not Path(sys.argv[2]).exists() and time.monotonic() < deadline:
    time.sleep(0.02)
"""


def _touch(path: Path, when: float) -> None:
    path.write_text("")
    os.utime(path, (when, when))


@pytest.mark.parametrize(
    ("record", "release", "expected"),
    [
        (None, None, False),  # a fresh ID
        (None, 1000.0, False),  # released cleanly: its record is gone
        (1000.0, None, True),  # a record and no release since: the holder died
        (1000.0, 2000.0, False),  # a later holder released the ID since
        (2000.0, 1000.0, True),  # died after the last release
        (1000.0, 1000.0, True),  # a coarse clock cannot tell: look
    ],
)
def test_died_holding_compares_the_record_with_the_last_release(
    lock_dir: Path, record: float | None, release: float | None, expected: bool
) -> None:
    (domain_id,) = free_ids(1)
    lock_dir.mkdir(exist_ok=True)
    if record is not None:
        _touch(record_path(lock_dir, domain_id, uid=12345), record)
    if release is not None:
        _touch(release_stamp(lock_dir, domain_id), release)
    assert died_holding(lock_dir, domain_id) is expected
    # Another ID's files say nothing about this one.
    assert not died_holding(lock_dir, domain_id + 1 if domain_id < 232 else 1)


def test_a_process_left_by_a_holder_that_died_holding_blocks_its_id(
    lock_dir: Path, children: Children
) -> None:
    """The holder's record is left behind, so the next reservation looks, finds, blocks."""
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    holder = children.python(HOLD_AND_LEAVE, lock_dir, domain_id)
    left = int(children.first_line(holder))
    try:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait(timeout=DEADLINE)
        assert record_path(lock_dir, domain_id).exists()  # what a clean release removes
        assert domain_id not in participants.bound_domains()  # nothing but the environment

        assert coordinator.try_reserve(["next"]) is None
        # What the look found is written down: the runners after it check a PID, not /proc.
        assert block_marker(lock_dir, domain_id).exists()
        assert coordinator.try_reserve(["next"]) is None
    finally:
        os.kill(left, signal.SIGKILL)
    _wait_gone(left)
    # The control: with the process gone, the same ID is handed out again.
    with coordinator.reserve(["next"]) as reservation:
        assert reservation.domain_id == domain_id


def test_after_a_clean_release_a_process_with_the_id_in_its_environment_costs_no_look(
    lock_dir: Path, children: Children
) -> None:
    """The common case: nobody died holding the ID, so no environment is read.

    A process carrying the ID in ROS_DOMAIN_ID without being a participant is not on
    the domain; the reservation goes ahead without scanning. The control is the same
    process after a holder died holding the ID: then it blocks the ID.
    """
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    coordinator.try_reserve(["first"]).release()  # type: ignore[union-attr]
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    bystander = children.start(["sleep", "300"], env=env)
    _wait_for_environment(bystander.pid, domain_id)

    with coordinator.reserve(["second"]) as reservation:
        assert reservation.domain_id == domain_id

    # The control: a holder dies holding the ID; the same bystander now blocks it.
    holder = children.python(HOLD_AND_LEAVE, lock_dir, domain_id)
    left = int(children.first_line(holder))
    os.kill(left, signal.SIGKILL)
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait(timeout=DEADLINE)
    _wait_gone(left)
    assert coordinator.try_reserve(["third"]) is None
    bystander.kill()
    bystander.wait(timeout=DEADLINE)
    with coordinator.reserve(["fourth"]) as reservation:
        assert reservation.domain_id == domain_id
    # A clean release after the look: the dead holder's record no longer counts.
    assert not died_holding(lock_dir, domain_id)


@capabilities.RCLPY
def test_a_runner_killed_while_its_test_is_between_participants_keeps_the_id_blocked(
    lock_dir: Path, env: dict[str, str], tmp_path: Path, children: Children
) -> None:
    """The runner gets SIGKILL; its test has closed one participant and not opened the next.

    No UDP port shows the test on its domain then: only the dead runner's record leads
    the next reservation to it.
    """
    (domain_id,) = free_ids(1)
    env["ROS_ISOLATED_TEST_DOMAINS"] = str(domain_id)
    pid_file, go = tmp_path / "test.pid", tmp_path / "go"
    script = BETWEEN_PARTICIPANTS
    runner = children.start(
        [CLI, "run", "--", sys.executable, "-c", script, str(pid_file), str(go)], env=env
    )
    try:
        wait_for(pid_file, timeout=DEADLINE)
        test_pid = int(pid_file.read_text())
        os.kill(runner.pid, signal.SIGKILL)
        assert runner.wait(timeout=DEADLINE) == -signal.SIGKILL
        os.kill(test_pid, 0)  # the test outlived its runner
        assert domain_id not in participants.bound_domains()

        assert DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"]) is None
    finally:
        go.touch()
    _wait_gone(test_pid)
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["x"]) as reservation:
        assert reservation.domain_id == domain_id


def _wait_for_environment(pid: int, domain_id: int) -> None:
    """Until the exec'd process shows the variable (a fork shows its parent's first)."""
    entry = f"ROS_DOMAIN_ID={domain_id}".encode()
    deadline = time.monotonic() + DEADLINE
    while entry not in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0"):
        assert time.monotonic() < deadline, "the process never showed its environment"
        time.sleep(0.01)


def _wait_gone(pid: int) -> None:
    """Until ``pid`` is gone (reaped by whoever its parent is now)."""
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            os.kill(pid, 0)
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (ProcessLookupError, FileNotFoundError):
            return
        if state in ("Z", "X"):
            return
        assert time.monotonic() < deadline, f"process {pid} did not end"
        time.sleep(0.02)
