"""``resource_holds``: the order of waiters, real holds on real flocks, and conflicts.

The order is checked on the decision itself (``Picture.may_go``: which waiter may take
what, given what is held and who came earlier); holding, death and release on real
files and processes; the end-to-end behaviour of runners is in e2e/test_resource_scheduling.
When the shared mutex was planted, this user's own lock file stands in for it.
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.domains import free_ids
from helpers.processes import poll_until, stat_of

from ros_isolated_test.domain_coordinator import resource_holds
from ros_isolated_test.domain_coordinator.queue import Queue, RunnerRecord, Waiter
from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
from ros_isolated_test.domain_coordinator.resource_holds import (
    CapacityConflictError,
    Demand,
    Hold,
    Picture,
)
from ros_isolated_test.domain_coordinator.waiting import PoolExhaustedError, ResourcesBusyError
from ros_isolated_test.process import proc

CAPACITY = {"cpu": 4, "gpu": 1}


def _holding(resources: dict[str, int]) -> Hold:
    return Hold(1, "someone", "a test", 0.0, "", resources, {}, 1)


def _board(held: list[dict[str, int]], waiting: list[Demand]) -> Picture:
    return Picture([_holding(item) for item in held], waiting, dict(CAPACITY))


def test_a_hold_and_a_waiter_show_the_fields_of_every_runner_alike() -> None:
    """``status --json``: one set of runner fields, a waiter's place before, a hold's ID after."""
    runner = RunnerRecord(12, "alice", "ros2 test", 5.0, "h", {"gpu": 1}).as_dict()
    waiter = Waiter(3, 12, "alice", "ros2 test", 5.0, "h", {"gpu": 1}).as_dict()
    hold = Hold(12, "alice", "ros2 test", 5.0, "h", {"gpu": 1}, {"gpu": 2}, 7, (99,)).as_dict()
    assert list(runner) == ["pid", "user", "command", "started", "host", "resources"]
    assert list(waiter.items()) == [("position", 3), *runner.items()]
    assert list(hold.items()) == [*runner.items(), ("domain_id", 7), ("survivors", [99])]
    assert "survivors" not in _holding({"gpu": 1}).as_dict()  # only a kept hold has them


def test_an_earlier_large_request_is_set_aside_before_later_small_ones() -> None:
    """No starvation: cpu=4 waiting first keeps later cpu=1 requests out of the 2 free CPUs."""
    big = Demand("1-big", {"cpu": 4}, domain=True)
    small = Demand("2-small", {"cpu": 1}, domain=True)
    board = _board([{"cpu": 2}], [big, small])
    assert board.may_go(small, small.name) == (False, False)
    # Control: without the large request ahead, the small one fits at once.
    assert _board([{"cpu": 2}], [small]).may_go(small, small.name) == (True, True)
    # And the large one itself waits for all four, however long the small ones take.
    assert board.may_go(big, big.name) == (False, False)
    assert _board([], [big, small]).may_go(big, big.name) == (True, True)


def test_a_waiter_held_up_by_a_device_holds_up_nobody_who_asks_for_other_things() -> None:
    gpu = Demand("1-gpu", {"gpu": 1}, domain=True)
    cpu = Demand("2-cpu", {"cpu": 1}, domain=True)
    id_only = Demand("3-id", {}, domain=True)
    board = _board([{"gpu": 1}], [gpu, cpu, id_only])
    assert board.may_go(cpu, cpu.name) == (True, True)
    # cpu=1 is free and comes earlier: it is to get an ID before the ID-only runner.
    assert board.may_go(id_only, id_only.name) == (True, False)
    # Control: with the GPU free, the GPU waiter comes first for an ID, as it arrived first.
    free_gpu = _board([], [gpu, id_only])
    assert free_gpu.may_go(id_only, id_only.name) == (True, False)
    assert _board([{"gpu": 1}], [gpu, id_only]).may_go(id_only, id_only.name) == (True, True)


def test_a_newcomer_without_a_ticket_comes_after_every_waiter() -> None:
    waiting = Demand("1-gpu", {"gpu": 1}, domain=True)
    newcomer = Demand("", {"gpu": 1}, domain=True)
    assert _board([], [waiting]).may_go(newcomer, None) == (False, False)
    # "" (no order asked): whatever is free now.
    assert _board([], [waiting]).may_go(newcomer, "") == (True, True)


def test_resources_without_an_id_wait_for_no_earlier_runner_waiting_for_an_id() -> None:
    id_only = Demand("1-id", {}, domain=True)
    disabled = Demand("2-gpu", {"gpu": 1}, domain=False)
    assert _board([], [id_only, disabled]).may_go(disabled, disabled.name) == (True, True)
    with_id = Demand("2-gpu", {"gpu": 1}, domain=True)
    assert _board([], [id_only, with_id]).may_go(with_id, with_id.name) == (True, False)


def _holder_process(lock_dir: Path, resources: str) -> subprocess.Popen[str]:
    """A process holding ``resources`` (a real hold) until killed; it prints when it holds."""
    script = (
        "import sys, time\n"
        "from pathlib import Path\n"
        "from ros_isolated_test.domain_coordinator import resource_holds, resources\n"
        "wanted = resources.parse(sys.argv[2], 'test')\n"
        "held = resource_holds.hold(Path(sys.argv[1]), ['holder'], wanted, wanted, None)\n"
        "assert held is not None\n"
        "print('held', flush=True)\n"
        "time.sleep(600)\n"
    )
    process = subprocess.Popen(
        [sys.executable, "-c", script, str(lock_dir), resources],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    assert process.stdout.readline().strip() == "held"
    return process


def test_a_hold_counts_while_its_runner_lives_and_nothing_after_sigkill(lock_dir: Path) -> None:
    process = _holder_process(lock_dir, "gpu=1")
    try:
        held = resource_holds.holds(lock_dir)
        assert [(hold.pid, hold.resources, hold.capacity) for hold in held] == [
            (process.pid, {"gpu": 1}, {"gpu": 1})
        ]
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    # The kernel dropped the flock: the record left behind holds nothing, and goes.
    assert resource_holds.holds(lock_dir) == []
    assert not list((lock_dir / resource_holds.HOLD_DIR).iterdir())


def test_a_planted_or_unlocked_record_holds_nothing(lock_dir: Path) -> None:
    folder = lock_dir / resource_holds.HOLD_DIR
    folder.mkdir(mode=0o1777)
    (folder / "00000000000000000001-1.r.ticket").write_text(
        '{"pid": 1, "resources": {"gpu": 1}, "capacity": {"gpu": 1}}'
    )
    assert resource_holds.holds(lock_dir) == []
    # Control: a real hold of the same is counted.
    process = _holder_process(lock_dir, "gpu=1")
    try:
        assert [hold.resources for hold in resource_holds.holds(lock_dir)] == [{"gpu": 1}]
    finally:
        process.kill()
        process.wait()


def test_runners_that_disagree_on_a_capacity_are_told(lock_dir: Path) -> None:
    process = _holder_process(lock_dir, "gpu=1")  # its capacity: gpu=1
    try:
        queue = Queue(lock_dir)
        with pytest.raises(CapacityConflictError, match=r"capacity of gpu.*ROS_ISOLATED_TEST_CAP"):
            resource_holds.picture(lock_dir, queue, {"gpu": 1}, {"gpu": 2})
        # Control: the same capacity, or a resource the holder was not given, is fine.
        assert resource_holds.picture(lock_dir, queue, {"gpu": 1}, {"gpu": 1}).free("gpu") == 0
        assert resource_holds.picture(lock_dir, queue, {"sim": 1}, {"sim": 2}).free("sim") == 2
    finally:
        process.kill()
        process.wait()


def test_an_id_and_resources_are_taken_together_or_not_at_all(lock_dir: Path) -> None:
    ids = free_ids(1)
    first = DomainCoordinator(lock_dir, ids, {"gpu": 1}, {"gpu": 1})
    held = first.acquire(["first"])
    try:
        assert held.holding is not None
        # The pool is empty now: a runner asking only for cpu (free) takes nothing.
        other = DomainCoordinator(lock_dir, ids, {"cpu": 1}, {"cpu": 2})
        with pytest.raises(PoolExhaustedError):
            other.acquire(["other"])
        assert [hold.resources for hold in resource_holds.holds(lock_dir)] == [{"gpu": 1}]
    finally:
        held.release()
    # Released together: no hold and the ID free.
    assert resource_holds.holds(lock_dir) == []
    again = DomainCoordinator(lock_dir, ids).acquire(["again"])
    again.release()


def test_a_busy_resource_fails_at_once_without_waiting_and_names_its_holder(
    lock_dir: Path,
) -> None:
    ids = free_ids(2)
    process = _holder_process(lock_dir, "gpu=1")
    try:
        coordinator = DomainCoordinator(lock_dir, ids, {"gpu": 1}, {"gpu": 1})
        with pytest.raises(ResourcesBusyError, match=rf"gpu=1 is not free.*pid {process.pid}"):
            coordinator.acquire(["waits"], wait_timeout=0)
        # Nothing of ours is left: no ID held, no hold.
        assert [hold.pid for hold in resource_holds.holds(lock_dir)] == [process.pid]
    finally:
        process.kill()
        process.wait()
    # Control: once the holder is gone, the same request gets both at once.
    reservation = DomainCoordinator(lock_dir, ids, {"gpu": 1}, {"gpu": 1}).acquire(["now"])
    assert reservation.domain_id in ids
    reservation.release()


def test_resources_without_an_id_hold_no_id(lock_dir: Path) -> None:
    coordinator = DomainCoordinator(lock_dir, free_ids(1), {"gpu": 1}, {"gpu": 1})
    hold = coordinator.hold_resources(["disabled"])
    try:
        [record] = resource_holds.holds(lock_dir)
        assert (record.domain_id, record.resources) == (None, {"gpu": 1})
        # The pool's one ID is still free for a runner that asks nothing.
        DomainCoordinator(lock_dir, coordinator.pool).acquire(["id"]).release()
    finally:
        hold.release()
    assert resource_holds.holds(lock_dir) == []


def test_a_waiting_runner_gets_the_resource_when_its_holder_dies(lock_dir: Path) -> None:
    process = _holder_process(lock_dir, "gpu=1")
    ids = free_ids(1)
    script = (
        "import sys\n"
        "from pathlib import Path\n"
        "from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator\n"
        "ids = [int(sys.argv[2])]\n"
        "c = DomainCoordinator(Path(sys.argv[1]), ids, {'gpu': 1}, {'gpu': 1})\n"
        "r = c.acquire(['waiter'], wait_timeout=120, on_wait=lambda m: print(m, flush=True))\n"
        "print('got', r.domain_id, flush=True)\n"
    )
    waiter = subprocess.Popen(
        [sys.executable, "-c", script, str(lock_dir), str(ids[0])],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert waiter.stdout is not None
        assert waiter.stdout.readline().startswith("waiting for gpu=1")
        poll_until(lambda: bool(Queue(lock_dir).waiters()), "the waiter queued")
        assert Queue(lock_dir).waiters()[0].resources == {"gpu": 1}
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        out, _ = waiter.communicate(timeout=120)
        assert f"got {ids[0]}" in out
    finally:
        for child in (process, waiter):
            if child.poll() is None:
                child.kill()
            child.wait()


def test_a_resource_lock_held_elsewhere_never_outlasts_the_wait_timeout(lock_dir: Path) -> None:
    """Whoever holds the lock (a stopped runner, another user) cannot keep a waiter forever."""
    ids = free_ids(1)
    script = (
        "import sys\n"
        "from pathlib import Path\n"
        "from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator\n"
        "c = DomainCoordinator(Path(sys.argv[1]), [int(sys.argv[2])], {'gpu': 1}, {'gpu': 1})\n"
        "try:\n"
        "    c.acquire(['waiter'], wait_timeout=float(sys.argv[3])).release()\n"
        "except Exception as error:\n"
        "    print(type(error).__name__)\n"
        "else:\n"
        "    print('got')\n"
    )

    def waiter(wait: str) -> str:
        done = subprocess.run(
            [sys.executable, "-c", script, str(lock_dir), str(ids[0]), wait],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import fcntl, os, sys, time\n"
            "fd = os.open(sys.argv[1], os.O_RDONLY | os.O_CREAT, 0o666)\n"
            "fcntl.flock(fd, fcntl.LOCK_EX)\n"
            "print('locked', flush=True)\n"
            "time.sleep(600)\n",
            str(lock_dir / resource_holds.MUTEX),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None
        assert holder.stdout.readline().strip() == "locked"
        assert waiter("1") == "PoolExhaustedError"
    finally:
        holder.kill()
        holder.wait()
    # Control: with the lock free, the same request gets its GPU at once.
    assert waiter("1") == "got"


def test_only_runners_ahead_or_holding_can_disagree_with_a_newcomer(lock_dir: Path) -> None:
    """A runner that queues later with another capacity is told; those waiting are not."""
    queue = Queue(lock_dir)
    mine = queue.enter(["first"], resource_holds.ticket_fields({"gpu": 1}, {"gpu": 1}, True), True)
    later = queue.enter(["later"], resource_holds.ticket_fields({"gpu": 1}, {"gpu": 2}, True), True)
    assert mine is not None and later is not None
    try:
        assert mine.name < later.name
        resource_holds.picture(lock_dir, queue, {"gpu": 1}, {"gpu": 1}, mine.name)
        # Control: the same look with the later ticket counted (a newcomer behind both).
        with pytest.raises(CapacityConflictError, match=f"runner pid {os.getpid()} has 2"):
            resource_holds.picture(lock_dir, queue, {"gpu": 1}, {"gpu": 1}, None)
        # And the later runner, looking at who is ahead of it, is told.
        with pytest.raises(CapacityConflictError, match="this one has 2"):
            resource_holds.picture(lock_dir, queue, {"gpu": 1}, {"gpu": 2}, later.name)
    finally:
        later.close()
        mine.close()


def test_a_planted_mutex_leaves_the_resources_to_this_users_own_lock_file(
    lock_dir: Path,
) -> None:
    os.mkfifo(lock_dir / resource_holds.MUTEX)
    own = lock_dir / f"resources.uid{os.getuid()}.lock"
    assert not own.exists()
    with resource_holds.mutex(lock_dir) as held:
        assert held
        assert stat.S_ISREG(os.lstat(own).st_mode)
    assert stat.S_ISFIFO(os.lstat(lock_dir / resource_holds.MUTEX).st_mode)


# -- survivors: a test's process the runner could not end keeps what it held ----------------


@pytest.fixture
def survivor() -> Iterator[subprocess.Popen[bytes]]:
    """A live process standing for one the runner could not end (its own, to end later)."""
    process = subprocess.Popen(["sleep", "600"])
    yield process
    process.kill()
    process.wait()


@pytest.mark.parametrize("with_id", [True, False], ids=["with-an-id", "isolation-disabled"])
def test_resources_stay_held_while_a_survivor_lives_and_come_free_after(
    lock_dir: Path, env: dict[str, str], survivor: subprocess.Popen[bytes], with_id: bool
) -> None:
    """Like the ID: released only once the test's whole tree is gone, even after its runner."""
    ids = free_ids(2)
    first = DomainCoordinator(lock_dir, ids[:1], {"gpu": 1}, {"gpu": 1})
    taken = first.acquire(["first"]) if with_id else first.hold_resources(["first"])
    record = taken.block_for([stat_of(survivor.pid)])
    taken.release()
    # The runner let go; the survivor keeps the GPU, and status names it.
    [kept] = resource_holds.holds(lock_dir)
    assert (kept.resources, kept.survivors) == ({"gpu": 1}, (survivor.pid,))
    assert f"survivor(s) {survivor.pid} of pid {os.getpid()}" in kept.describe()
    assert kept.as_dict()["survivors"] == [survivor.pid]
    shown = run_cli(["status"], env)
    assert f"(survivors {survivor.pid}) first" in shown.stdout, shown.stdout
    rows = json.loads(run_cli(["status", "--json"], env).stdout)
    assert [row.get("survivors") for row in rows if row["via"] == "hold"] == [[survivor.pid]]
    other = DomainCoordinator(lock_dir, ids[1:], {"gpu": 1}, {"gpu": 1})
    with pytest.raises(ResourcesBusyError, match=rf"survivor\(s\) {survivor.pid} "):
        other.acquire(["second"])
    # The control: once it is gone the kept hold counts for nothing, and is removed.
    survivor.kill()
    survivor.wait()
    again = other.acquire(["third"])
    again.release()
    assert resource_holds.holds(lock_dir) == []
    kept_files = list((lock_dir / resource_holds.HOLD_DIR).glob("*" + resource_holds.KEPT))
    assert kept_files == [], kept_files
    assert with_id == record.name.endswith(".blocked")


def test_a_kept_hold_of_a_recycled_pid_another_boot_or_a_planted_file_holds_nothing(
    lock_dir: Path, survivor: subprocess.Popen[bytes]
) -> None:
    coordinator = DomainCoordinator(lock_dir, free_ids(1), {"gpu": 1}, {"gpu": 1})
    hold = coordinator.hold_resources(["first"])
    path = hold.block_for([stat_of(survivor.pid)])
    hold.release()
    text = path.read_text()
    # Control: as written, it holds the GPU.
    assert [item.survivors for item in resource_holds.holds(lock_dir)] == [(survivor.pid,)]
    start = stat_of(survivor.pid).start
    for changed in (
        text.replace(f"[{survivor.pid}, {start}]", f"[{survivor.pid}, {start + 1}]"),  # recycled
        text.replace(proc.boot_id(), "another-boot"),
        '{"resources": {"gpu": 1}, "capacity": {"gpu": 1}, "survivors": "all"}',
    ):
        assert changed != text
        path.write_text(changed)
        assert resource_holds.holds(lock_dir) == [], changed
        path.write_text(text)
        assert len(resource_holds.holds(lock_dir)) == 1
