"""``waiting``: a runner that finds no ID free waits in line, first come, first served.

It takes a ticket and tries only when its turn has come: with real tickets in the queue
a newcomer never jumps an earlier waiter, even with an ID free, and real waiting
processes get a held ID in the order they came, each told once why it waits and how
many are ahead. A runner that gets nothing gives up with one line naming who holds the
pool and what to do (at once with no wait, ``after waiting`` otherwise), and the real
CLI then exits 3 without running the test; the control each time is the same request
once the ID is free.
"""

from __future__ import annotations

import os
import pwd
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.coordinator import error_lines
from helpers.domains import free_ids
from helpers.processes import Children
from helpers.results import result_error

from ros_isolated_test.domain_coordinator import POOL_ENV, DomainCoordinator, PoolExhaustedError
from ros_isolated_test.domain_coordinator.queue import Queue
from ros_isolated_test.domain_coordinator.reservation import Reservation
from ros_isolated_test.domain_coordinator.waiting import Waiting

#: Waits for argv[2], the only ID of its pool, printing each waiting line; then writes its
#: name (argv[3]) into the order file (argv[4]), says so, and lets go. argv[1]: lock dir.
WAITER = """
import sys
from pathlib import Path
from ros_isolated_test.domain_coordinator import DomainCoordinator
lock_dir, domain_id, name, order = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
reservation = DomainCoordinator(lock_dir, (domain_id,)).acquire(
    [name], wait_timeout=120, on_wait=lambda line: print(line, flush=True)
)
with open(order, "a") as out:
    out.write(name + "\\n")
print("got", reservation.domain_id, flush=True)
reservation.release()
"""


def _me() -> str:
    return pwd.getpwuid(os.getuid()).pw_name


def test_a_pool_with_every_id_held_is_exhausted(lock_dir: Path) -> None:
    ids = free_ids(2)
    coordinator = DomainCoordinator(lock_dir, ids)
    with coordinator.reserve(["a"]), coordinator.reserve(["b"]):
        assert coordinator.try_reserve(["c"]) is None
        with pytest.raises(PoolExhaustedError) as raised, coordinator.reserve(["c"]):
            pass
    message = str(raised.value)
    assert "all 2 IDs of the pool are in use" in message
    assert "ros-isolated-test status" in message
    assert POOL_ENV in message
    assert "\n" not in message


def test_run_with_the_pool_exhausted_exits_3_and_says_so(
    lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    ids = free_ids(2)
    marker = tmp_path / "ran"
    result_file = tmp_path / "out" / "exhausted.xml"
    env[POOL_ENV] = ",".join(map(str, ids))
    coordinator = DomainCoordinator(lock_dir, ids)
    with coordinator.reserve(["a"]), coordinator.reserve(["b"]):
        result = run_cli(
            [
                "run",
                "--wait-timeout",
                "0",
                "--junit-xml",
                str(result_file),
                "--",
                "touch",
                str(marker),
            ],
            env,
        )
    assert result.returncode == 3, result.stdout + result.stderr
    lines = error_lines(result.stderr)
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(
        "ros-isolated-test: error: no free ROS_DOMAIN_ID: all 2 IDs of the pool are in use"
    )
    assert not marker.exists()
    assert "all 2 IDs of the pool are in use" in result_error(result_file)


def test_giving_up_names_who_holds_the_pool(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    waiting = Waiting(lock_dir, (domain_id,), {}, {})

    def take(domain: bool) -> Reservation | None:
        assert domain
        return coordinator.try_reserve(["newcomer"])

    with coordinator.reserve(["holder", "--of", "the pool"]):
        for wait_timeout, spent in ((0.0, ""), (0.2, "after waiting 0 s, ")):
            with pytest.raises(PoolExhaustedError) as raised:
                waiting.wait(["newcomer"], wait_timeout, None, True, take)
            message = str(raised.value)
            assert message.startswith(f"{spent}no free ROS_DOMAIN_ID: all 1 IDs"), message
            assert f"{domain_id}: pid {os.getpid()} ({_me()}) holder --of 'the pool'" in message
            assert "\n" not in message
    assert Queue(lock_dir).waiters() == []  # the ticket of the wait went with it
    # The control: the same wait with the ID free takes it at once.
    taken = waiting.wait(["newcomer"], 0.0, None, True, take)
    assert taken.domain_id == domain_id
    taken.release()


def test_the_waiting_line_says_whether_ids_are_free_for_earlier_waiters(lock_dir: Path) -> None:
    first, second = free_ids(2)
    waiting = Waiting(lock_dir, (first, second), {}, {})
    with DomainCoordinator(lock_dir, (first,)).reserve(["one"]):
        line = waiting.waiting_message(2, 1.5, 30.0)
        assert line.startswith("waiting for a free ROS_DOMAIN_ID (1.5 s of 30 s, 2 runner(s) ")
        assert "1 of 2 IDs free, for earlier waiters first" in line
        assert f"{first}: pid {os.getpid()} " in line
        with DomainCoordinator(lock_dir, (second,)).reserve(["two"]):
            line = waiting.waiting_message(0, 3.0, 30.0)  # the control: none free
    assert "all 2 IDs of the pool are in use" in line
    assert f"{second}: pid {os.getpid()} " in line


def test_a_newcomer_never_takes_a_free_id_before_an_earlier_waiter(lock_dir: Path) -> None:
    """Real tickets in the queue; the ID is free throughout, so only the order decides."""
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    waiting = Waiting(lock_dir, (domain_id,), {}, {})
    tried: list[str] = []

    def take(domain: bool) -> Reservation | None:
        tried.append("take")
        return coordinator.try_reserve(["t"])

    queue = Queue(lock_dir)
    earlier, later = queue.enter(["earlier"]), queue.enter(["later"])
    assert earlier is not None and later is not None
    try:
        assert earlier.name < later.name
        for before in (None, later.name):  # a newcomer without a ticket, then the later one
            assert waiting.attempt(queue, before, True, take) == (None, False)
        assert tried == []
        taken, turn = waiting.attempt(queue, earlier.name, True, take)  # the earlier one's turn
        assert turn and taken is not None and taken.domain_id == domain_id
        taken.release()
        # Not waiting at all (""): whatever is free now, whoever waits.
        taken, turn = waiting.attempt(queue, "", True, take)
        assert turn and taken is not None
        taken.release()
    finally:
        later.close()
        earlier.close()
    # The control: nobody waits any more, and the newcomer takes the ID.
    taken, turn = waiting.attempt(queue, None, True, take)
    assert turn and taken is not None
    taken.release()


def test_waiting_processes_get_a_held_id_in_the_order_they_came(
    lock_dir: Path, tmp_path: Path, children: Children
) -> None:
    (domain_id,) = free_ids(1)
    order = tmp_path / "order"
    holder = DomainCoordinator(lock_dir, (domain_id,)).acquire(["holder"])
    try:
        first = children.python(WAITER, lock_dir, domain_id, "first", order)
        told_first = children.first_line(first)
        second = children.python(WAITER, lock_dir, domain_id, "second", order)
        told_second = children.first_line(second)
    finally:
        holder.release()
    for told, ahead in ((told_first, 0), (told_second, 1)):
        assert told.startswith("waiting for a free ROS_DOMAIN_ID ("), told
        assert f"{ahead} runner(s) ahead): all 1 IDs of the pool are in use" in told, told
        assert f"{domain_id}: pid {os.getpid()} ({_me()}) holder" in told, told
    assert children.finish(first) == 0
    assert children.finish(second) == 0
    assert order.read_text().split() == ["first", "second"]
