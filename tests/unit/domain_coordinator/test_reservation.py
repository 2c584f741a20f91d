"""``reservation``: holding a domain ID on a flock'ed file and upstream's TCP port.

With real locks, sockets and processes: an ID goes to one holder at a time, in this
process or any other; release (or leaving the ``with`` block, by an exception too)
makes it free again, and the lock file stays, shared by every user whatever the umask.
The kernel drops a flock however its holder dies: a SIGKILLed holder frees its ID at
once, and a SIGKILLed runner's lock and port do not leak into its test, though the
orphaned test still keeps the ID out of use. IDs go least recently released first, and
``reserve_if_free`` never takes the ID an earlier waiter is to have. (Planted lock
files and records: ``test_reservation_hostile``; the pool exhausted: ``test_waiting``.)

Ports 32768+ID are machine-wide, so tests pick IDs whose port is free right now, from
215-232 where they can: outside the default pool and upstream's 1-100, so that other
runs on this machine rarely contend with them.
"""

from __future__ import annotations

import os
import signal
import stat
import sys
import time
from pathlib import Path

import pytest
from helpers.commands import CLI
from helpers.coordinator import HOLD_SCRIPT
from helpers.domains import free_ids
from helpers.orphans import in_background
from helpers.processes import DEADLINE, WAIT_SCRIPT, Children, user_keywords, wait_for

from ros_isolated_test.domain_coordinator import POOL_ENV, DomainCoordinator, domain_uses
from ros_isolated_test.domain_coordinator.lock_files import lock_path
from ros_isolated_test.domain_coordinator.port_guard import port_is_taken
from ros_isolated_test.domain_coordinator.queue import Queue

# -- reserving and releasing --------------------------------------------------------------


def test_reserve_gives_the_first_free_id(lock_dir: Path) -> None:
    first, second, third = free_ids(3)
    coordinator = DomainCoordinator(lock_dir, (first, second, third))
    with coordinator.reserve(["test"]) as reservation:
        assert reservation.domain_id == first
    with DomainCoordinator(lock_dir, (third, first)).reserve(["test"]) as reservation:
        assert reservation.domain_id == third


def test_two_reservations_in_one_process_differ(lock_dir: Path) -> None:
    ids = free_ids(3)
    coordinator = DomainCoordinator(lock_dir, ids)
    with coordinator.reserve(["a"]) as one, coordinator.reserve(["b"]) as two:
        assert one.domain_id == ids[0]
        # Equally old IDs (none ever released here): which one comes next is the PID's.
        assert two.domain_id in ids[1:]
        with DomainCoordinator(lock_dir, ids).reserve(["c"]) as three:
            assert {one.domain_id, two.domain_id, three.domain_id} == set(ids)


def test_release_makes_the_id_free_again(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    reservation = coordinator.try_reserve(["a"])
    assert reservation is not None
    assert coordinator.try_reserve(["b"]) is None
    assert port_is_taken(domain_id)
    reservation.release()
    assert reservation.released
    reservation.release()  # twice is harmless
    assert not port_is_taken(domain_id)
    again = coordinator.try_reserve(["c"])
    assert again is not None
    assert again.domain_id == domain_id
    again.release()


def test_leaving_the_block_by_an_exception_releases(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    with pytest.raises(KeyboardInterrupt), coordinator.reserve(["a"]):
        raise KeyboardInterrupt
    assert domain_uses(lock_dir, (domain_id,)) == []
    with coordinator.reserve(["b"]) as reservation:
        assert reservation.domain_id == domain_id


def test_lock_file_stays_after_release_and_is_shared(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    path = lock_path(lock_dir, domain_id)
    old_umask = os.umask(0o077)
    try:
        with DomainCoordinator(lock_dir, (domain_id,)).reserve(["a"]):
            assert path.is_file()
            inode = path.stat().st_ino
    finally:
        os.umask(old_umask)
    assert path.is_file(), "the lock file must never be unlinked"
    assert path.stat().st_ino == inode
    assert stat.S_IMODE(path.stat().st_mode) == 0o666
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["b"]):
        assert path.stat().st_ino == inode
    assert path.stat().st_ino == inode


def test_the_least_recently_released_id_comes_first(lock_dir: Path) -> None:
    """Discovery data a finished test left has the most time to expire before reuse."""
    first, second = free_ids(2)
    coordinator = DomainCoordinator(lock_dir, (first, second))
    with coordinator.reserve(["a"]) as reservation:
        assert reservation.domain_id == first  # the control: never released, pool order
    with coordinator.reserve(["b"]) as reservation:
        assert reservation.domain_id == second  # `first` was just released
    assert coordinator.candidates() == [first, second]


def test_reserving_if_free_leaves_the_id_to_an_earlier_waiter(lock_dir: Path) -> None:
    """A test in namespaces of its own never takes the ID a queued runner waits for."""
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    ticket = Queue(lock_dir).enter(["waiting"])
    assert ticket is not None
    try:
        assert coordinator.reserve_if_free(["no wait"]) is None
        assert not domain_uses(lock_dir, (domain_id,))  # the ID itself is free
    finally:
        ticket.close()
    # The control: nobody waits any more, and the same call takes the ID.
    reservation = coordinator.reserve_if_free(["no wait"])
    assert reservation is not None
    assert reservation.domain_id == domain_id
    reservation.release()


# -- holders that die ----------------------------------------------------------------------


def test_a_sigkilled_holder_frees_its_id_at_once(lock_dir: Path, children: Children) -> None:
    (domain_id,) = free_ids(1)
    child = children.python(HOLD_SCRIPT, lock_dir, domain_id)
    assert children.first_line(child) == str(domain_id)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    assert coordinator.try_reserve(["parent"]) is None
    (held,) = domain_uses(lock_dir, (domain_id,))
    assert held.holder is not None
    assert held.holder.pid == child.pid

    os.kill(child.pid, signal.SIGKILL)
    assert child.wait(timeout=DEADLINE) == -signal.SIGKILL
    # The killed child left its holder record behind; the lock is what counts.
    assert domain_uses(lock_dir, (domain_id,)) == []
    reservation = coordinator.try_reserve(["parent"])
    assert reservation is not None
    assert reservation.domain_id == domain_id
    reservation.release()


def test_a_sigkilled_runner_frees_its_lock_and_port_but_its_test_still_blocks_the_id(
    lock_dir: Path, env: dict[str, str], tmp_path: Path, children: Children
) -> None:
    """Neither the lock nor the port leaks into the test process the runner started, but
    the orphaned test still talks on the domain: the squatter scan keeps the ID out of use.
    """
    (domain_id,) = free_ids(1)
    env[POOL_ENV] = str(domain_id)
    pid_file, go = tmp_path / "test.pid", tmp_path / "go"
    test = [sys.executable, "-c", WAIT_SCRIPT, str(pid_file), str(go)]
    runner = children.start([CLI, "run", "--", *in_background(test)], env=env)
    wait_for(pid_file)
    test_pid = int(pid_file.read_text())
    try:
        assert port_is_taken(domain_id)
        assert DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"]) is None
        os.kill(runner.pid, signal.SIGKILL)
        assert runner.wait(timeout=DEADLINE) == -signal.SIGKILL
        os.kill(test_pid, 0)  # the test process is still running
        assert not port_is_taken(domain_id)
        assert DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"]) is None
        go.touch()
        deadline = time.monotonic() + DEADLINE
        while time.monotonic() < deadline:
            reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"])
            if reservation is not None:
                reservation.release()
                break
            time.sleep(0.05)
        else:
            pytest.fail("the ID stayed blocked after the orphan ended")
    finally:
        go.touch()


# -- every user on the machine shares the lock directory -----------------------------------


def test_users_share_lock_files_and_the_lock_dir(traversable_dir: Path, children: Children) -> None:
    nobody, daemon = 65534, 1  # traversable_dir requires both users
    first, second = free_ids(2)
    lock_dir = traversable_dir / "locks"

    # nobody creates the lock dir and the lock file of `first`, under umask 077.
    by_nobody = children.python(HOLD_SCRIPT, lock_dir, first, **user_keywords(nobody))
    assert children.first_line(by_nobody) == str(first)
    assert lock_dir.stat().st_uid == nobody
    assert stat.S_IMODE(lock_dir.stat().st_mode) == 0o1777
    assert lock_path(lock_dir, first).stat().st_uid == nobody
    assert stat.S_IMODE(lock_path(lock_dir, first).stat().st_mode) == 0o666

    # daemon, another user, finds `first` held by nobody and takes `second`.
    by_daemon = children.python(HOLD_SCRIPT, lock_dir, first, second, **user_keywords(daemon))
    assert children.first_line(by_daemon) == str(second)
    held = {item.domain_id: item for item in domain_uses(lock_dir, (first, second))}
    assert set(held) == {first, second}
    first_holder, second_holder = held[first].holder, held[second].holder
    assert first_holder is not None and second_holder is not None
    assert (first_holder.user, first_holder.pid) == ("nobody", by_nobody.pid)
    assert (second_holder.user, second_holder.pid) == ("daemon", by_daemon.pid)
    assert DomainCoordinator(lock_dir, (first, second)).try_reserve(["root"]) is None

    assert children.finish(by_nobody) == 0
    assert children.finish(by_daemon) == 0
    assert domain_uses(lock_dir, (first, second)) == []
    # daemon can now lock the file nobody created, and nobody the one daemon created.
    swapped = children.python(HOLD_SCRIPT, lock_dir, first, **user_keywords(daemon))
    assert children.first_line(swapped) == str(first)
    assert children.finish(swapped) == 0
    swapped = children.python(HOLD_SCRIPT, lock_dir, second, **user_keywords(nobody))
    assert children.first_line(swapped) == str(second)
    assert children.finish(swapped) == 0
