"""``escaped``: a holder that died holding its ID, the only case where a reservation looks at /proc.

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
from helpers.coordinator import wait_for_environment, wait_gone
from helpers.domains import free_ids
from helpers.orphans import in_background
from helpers.processes import DEADLINE, Children, wait_for
from helpers.tiny_disk import run_on_tiny_disk

from ros_isolated_test.domain_coordinator import DomainCoordinator, participants
from ros_isolated_test.domain_coordinator.block import block_marker
from ros_isolated_test.domain_coordinator.escaped import died_holding
from ros_isolated_test.domain_coordinator.records import record_path
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


def _made_after(path: Path, earlier: Path | None, owner: int | None = None) -> None:
    """Create ``path`` (owned by ``owner``), its change time after ``earlier``'s.

    A coarse file clock can give both one time: touched again until it moves on.
    """
    path.write_text("")
    if owner is not None:
        os.chown(path, owner, owner)
    while earlier is not None and os.stat(path).st_ctime <= os.stat(earlier).st_ctime:
        time.sleep(0.005)
        os.utime(path)


@pytest.mark.parametrize(
    ("events", "expected"),
    [
        ((), False),  # a fresh ID
        (("release",), False),  # released cleanly: its record is gone
        (("record",), True),  # a record and no release since: the holder died
        (("record", "release"), False),  # a later holder released the ID since
        (("release", "record"), True),  # died after the last release
    ],
)
def test_died_holding_compares_the_record_with_the_last_release(
    lock_dir: Path, events: tuple[str, ...], expected: bool
) -> None:
    (domain_id,) = free_ids(1)
    lock_dir.mkdir(exist_ok=True)
    paths = {
        "record": record_path(lock_dir, domain_id),
        "release": release_stamp(lock_dir, domain_id),
    }
    earlier: Path | None = None
    for event in events:
        _made_after(paths[event], earlier)
        earlier = paths[event]
    assert died_holding(lock_dir, domain_id) is expected
    # Another ID's files say nothing about this one.
    assert not died_holding(lock_dir, domain_id + 1 if domain_id < 232 else 1)


def test_a_future_time_set_on_a_release_stamp_does_not_clear_a_record(lock_dir: Path) -> None:
    """utime sets any modification time; the change time it cannot set is what counts."""
    (domain_id,) = free_ids(1)
    lock_dir.mkdir(exist_ok=True)
    stamp, record = release_stamp(lock_dir, domain_id), record_path(lock_dir, domain_id)
    _made_after(stamp, None)
    _made_after(record, stamp)
    year_2100 = 4102444800.0
    os.utime(stamp, (year_2100, year_2100))
    assert died_holding(lock_dir, domain_id)
    # The control: a release after the record clears it.
    os.utime(stamp)
    _made_after(stamp, record)
    assert not died_holding(lock_dir, domain_id)


@capabilities.ROOT
@pytest.mark.parametrize(
    ("stamp_owner", "expected"),
    [(4243, True), (4242, False), (0, False)],
    ids=["another-user", "the-same-user", "root"],
)
def test_only_a_release_by_the_dead_holders_user_or_root_clears_its_record(
    lock_dir: Path, stamp_owner: int, expected: bool
) -> None:
    """Another user's look could not read that holder's processes' environments."""
    (domain_id,) = free_ids(1)
    lock_dir.mkdir(exist_ok=True)
    record = record_path(lock_dir, domain_id, uid=4242)
    _made_after(record, None, owner=4242)
    _made_after(lock_dir / f"domain-{domain_id}.uid{stamp_owner}.released", record, stamp_owner)
    assert died_holding(lock_dir, domain_id) is expected


#: On a tiny disk: hold an ID, fill the disk (argv[3] "full") or not, record survivors,
#: release; print whether the block was written and whether the next holder will look.
BLOCK_ON_A_FULL_DISK = """
import os, subprocess, sys
from pathlib import Path
from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.domain_coordinator.escaped import died_holding
from ros_isolated_test.process import proc
lock_dir, domain_id = Path(sys.argv[1]), int(sys.argv[2])
reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["t"])
assert reservation is not None
if sys.argv[3] == "full":
    subprocess.run(["dd", "if=/dev/zero", f"of={lock_dir.parent}/filler", "bs=1k"],
                   stderr=subprocess.DEVNULL)
try:
    reservation.block_for([proc.read_stat(os.getpid())])
    blocked = "blocked"
except OSError:
    blocked = "not-blocked"
reservation.release()
print(blocked, "look" if died_holding(lock_dir, domain_id) else "no-look", flush=True)
"""


@capabilities.MOUNT_NAMESPACE
@pytest.mark.parametrize(
    ("disk", "expected"), [("full", "not-blocked look"), ("room", "blocked no-look")]
)
def test_survivors_that_cannot_be_recorded_leave_the_release_unclean(
    tmp_path: Path, env: dict[str, str], disk: str, expected: str
) -> None:
    """No block record names them, so the next holder must look for them in /proc.

    The control has room for the block record: the release is clean, the block does it.
    """
    (domain_id,) = free_ids(1)
    mount = tmp_path / "disk"
    argv = [sys.executable, "-c", BLOCK_ON_A_FULL_DISK, str(mount / "locks"), str(domain_id), disk]
    done = run_on_tiny_disk(mount, argv, env, size="256k")
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    assert done.stdout.decode().split() == expected.split()


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
    wait_gone(left)
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
    wait_for_environment(bystander.pid, domain_id)

    with coordinator.reserve(["second"]) as reservation:
        assert reservation.domain_id == domain_id

    # The control: a holder dies holding the ID; the same bystander now blocks it.
    holder = children.python(HOLD_AND_LEAVE, lock_dir, domain_id)
    left = int(children.first_line(holder))
    os.kill(left, signal.SIGKILL)
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait(timeout=DEADLINE)
    wait_gone(left)
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
    test = [sys.executable, "-c", script, str(pid_file), str(go)]
    runner = children.start([CLI, "run", "--", *in_background(test)], env=env)
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
    wait_gone(test_pid)
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["x"]) as reservation:
        assert reservation.domain_id == domain_id
