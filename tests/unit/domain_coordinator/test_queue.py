"""``queue``: first come, first served among waiting runners, against a hostile lock directory.

Each waiter holds a flock on a ticket named after its arrival time; real runners queue
behind a real holder and are served in arrival order. A planted ``queue`` entry (a file,
a symlink, another user's folder) must not turn off first come, first served: runners
queue in a folder of their own user instead and say so, and nothing is made or removed
through a link. A planted ticket record must not break ``status`` or a waiting runner:
a record is read only from a regular file, its fields only as far as they are valid.
"""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, HUNG, run_cli, start_cli
from helpers.coordinator import PRINT_ID, hold_the_pool
from helpers.hostile_lock_dir import (
    NOBODY,
    granted_id,
    pick_ids,
    plant_file,
    run_timed,
    shared_env,
    snapshot,
    tree,
)
from helpers.processes import DEADLINE, Children, poll_until

from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.domain_coordinator.queue import Queue
from ros_isolated_test.process import proc

WAITERS = 5
NOTE = "the shared queue folder"
FORGED = "FORGED-LINE"


def _tickets(lock_dir: Path) -> list[Path]:
    """Every ticket in any queue folder (shared or per user), never through a link."""
    return [
        ticket
        for folder in lock_dir.glob("queue*")
        if folder.is_dir() and not folder.is_symlink()
        for ticket in folder.glob("*.ticket")
    ]


def _plant_queue(kind: str, lock_dir: Path, tmp_path: Path) -> Path | None:
    path = lock_dir / "queue"
    if kind == "regular file":
        path.write_text("planted\n")
    elif kind == "symlink":
        elsewhere = tmp_path / "elsewhere"
        elsewhere.mkdir()
        path.symlink_to(elsewhere)
    elif kind == "directory of another user":
        path.mkdir(mode=0o755)
        os.chown(path, NOBODY, NOBODY)  # no sticky bit: its owner could drop our tickets
    else:
        return None
    return path


KINDS = [
    "healthy",
    "regular file",
    "symlink",
    pytest.param("directory of another user", marks=capabilities.ROOT.mark),
]


@pytest.mark.parametrize("kind", KINDS)
def test_waiters_are_served_in_arrival_order_even_with_a_planted_queue(
    kind: str,
    one_id: dict[str, str],
    tmp_path: Path,
    started: list[subprocess.Popen[bytes]],
) -> None:
    lock_dir = Path(one_id["ROS_ISOLATED_TEST_LOCK_DIR"])
    planted = _plant_queue(kind, lock_dir, tmp_path)
    go = hold_the_pool(one_id, tmp_path, started)
    order = tmp_path / "order"
    waiters = []
    for index in range(WAITERS):
        waiter = start_cli(
            ["run", "--wait-timeout", "120", "--", "sh", "-c", f"echo {index} >> {order}"],
            one_id,
            tmp_path / f"waiter{index}.log",
            started,
        )
        waiters.append(waiter)

        def queued(count: int = index + 1, waiter: subprocess.Popen[bytes] = waiter) -> bool:
            assert waiter.poll() is None, (tmp_path / f"waiter{count - 1}.log").read_text()
            return len(_tickets(lock_dir)) == count

        poll_until(queued, f"waiter {index} never took a ticket")

    shown = run_cli(["status", "--json"], one_id)
    rows = json.loads(shown.stdout)
    queue = [(row["position"], row["pid"]) for row in rows if row["via"] == "queue"]
    assert queue == [(index + 1, waiter.pid) for index, waiter in enumerate(waiters)]
    notes = [line for line in shown.stderr.splitlines() if "note:" in line]

    go.touch()
    for index, waiter in enumerate(waiters):
        assert waiter.wait(HUNG) == 0, (tmp_path / f"waiter{index}.log").read_text()
    assert order.read_text().split() == [str(index) for index in range(WAITERS)]

    logs = [(tmp_path / f"waiter{index}.log").read_text() for index in range(WAITERS)]
    if planted is None:  # control: a healthy queue says nothing
        assert notes == []
        assert not any(NOTE in log for log in logs), logs
        return
    assert len(notes) == 1 and str(planted) in notes[0], notes
    for log in logs:  # once per runner, naming the planted path
        (line,) = [line for line in log.splitlines() if NOTE in line]
        assert str(planted) in line and f"queue.uid{os.getuid()}" in line, line
    if kind == "regular file":
        assert planted.read_text() == "planted\n"
    elif kind == "symlink":
        assert list(planted.resolve().iterdir()) == []  # nothing made through the link


def _plant_ticket(lock_dir: Path, name: str, content: bytes) -> int:
    """A ticket held (flock'ed) by this test process: live, as a planter's would be."""
    folder = lock_dir / "queue"
    if not folder.exists():
        folder.mkdir()
        folder.chmod(0o1777)
    fd = os.open(folder / name, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
    os.write(fd, content)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return fd


def _name() -> str:
    """A ticket name after every waiter's so far: the planted ticket is behind them."""
    return f"{time.time_ns() + 10**12:020d}-4242.ticket"


#: name -> (ticket name, record). Each crashed status or forged a line before the fix.
HOSTILE_TICKETS: dict[str, tuple[Callable[[], str], bytes]] = {
    "pid 1e999": (_name, b'{"pid": 1e999, "user": "u", "command": "c", "started": 1}'),
    "started 1e300": (_name, b'{"pid": 4242, "user": "u", "command": "c", "started": 1e300}'),
    "started Infinity": (_name, b'{"pid": 4242, "command": "c", "started": Infinity}'),
    "not an object": (_name, b'"just a string"'),
    "deeply nested": (_name, b"{" + b'"a": [' * 30_000),
    "invalid UTF-8": (_name, b'{"pid": 4242, "command": "\xff\xfe", "started": 1}'),
    "huge": (_name, b'{"pid": 4242, "command": "' + b"x" * 300_000 + b'"}'),
    "a 200-digit arrival time": (lambda: "9" * 200 + "-4242.ticket", b"{}"),
    "digits int() refuses": (lambda: "9\u00b2-\u00b2.ticket", b"{}"),
}


@pytest.mark.parametrize("variant", sorted(HOSTILE_TICKETS))
def test_a_planted_ticket_breaks_neither_status_nor_the_queue(
    variant: str, one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    lock_dir = Path(one_id["ROS_ISOLATED_TEST_LOCK_DIR"])
    go = hold_the_pool(one_id, tmp_path, started)
    waiter = start_cli(
        ["run", "--wait-timeout", "120", "--", "echo", "waiter-marker"],
        one_id,
        tmp_path / "waiter.log",
        started,
    )
    poll_until(lambda: len(_tickets(lock_dir)) == 1, "the waiter never took a ticket")
    name, content = HOSTILE_TICKETS[variant]
    fd = _plant_ticket(lock_dir, name(), content)
    try:
        listed = run_cli(["status", "--json"], one_id)
        assert listed.returncode == 0, listed.stdout + listed.stderr
        queue = [row for row in json.loads(listed.stdout) if row["via"] == "queue"]
        # Control: the real waiter is first, with its real PID and command.
        assert (queue[0]["position"], queue[0]["pid"]) == (1, waiter.pid), queue
        assert "echo waiter-marker" in str(queue[0]["command"])
        assert len(queue) == 2, queue  # the planted one is still a live ticket
        table = run_cli(["status"], one_id)
        assert table.returncode == 0, table.stdout + table.stderr
        assert f" {waiter.pid} " in table.stdout
    finally:
        os.close(fd)
    go.touch()
    assert waiter.wait(HUNG) == 0, (tmp_path / "waiter.log").read_text()
    assert "waiter-marker" in (tmp_path / "waiter.log").read_text()


def test_a_planted_ticket_command_forges_no_line_in_status(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    lock_dir = Path(one_id["ROS_ISOLATED_TEST_LOCK_DIR"])
    go = hold_the_pool(one_id, tmp_path, started)
    forged = f"c\r\n  1   4242  root  2024-01-01T00:00:00  {FORGED}\x1b[2K"
    record = json.dumps({"pid": 4242, "command": forged, "started": time.time()}).encode()
    fd = _plant_ticket(lock_dir, _name(), record)
    try:
        table = run_cli(["status"], one_id)
    finally:
        os.close(fd)
    assert table.returncode == 0, table.stdout + table.stderr
    assert "\r" not in table.stdout and "\x1b" not in table.stdout, table.stdout
    (line,) = [line for line in table.stdout.splitlines() if FORGED in line]
    assert line.split()[:2] == ["1", "4242"] and "c\\x0d\\x0a" in line, line
    go.touch()


def test_listing_the_queue_reads_pid_max_once_whatever_the_tickets(
    lock_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each ticket's name is checked against one pid_max, not a fresh /proc read per ticket.

    The PIDs come from the names (the records hold none), so the limit is still applied:
    a name's PID at or above pid_max shows as 0.
    """
    reads: list[int] = []

    def counted() -> int:
        reads.append(real())
        return reads[-1]

    real = proc.pid_max
    monkeypatch.setattr(proc, "pid_max", counted)
    limit = real()
    names = [f"{time.time_ns() + step:020d}-{pid}.ticket" for step, pid in enumerate((7, limit, 9))]
    fds = [_plant_ticket(lock_dir, name, b"{}") for name in names]
    try:
        waiters = Queue(lock_dir).waiters()
    finally:
        for fd in fds:
            os.close(fd)
    assert [waiter.pid for waiter in waiters] == [7, 0, 9]
    assert len(reads) == 1


def test_a_ticket_record_planted_by_nobody_trustworthy_is_read_safely(
    lock_dir: Path,
) -> None:
    """A ticket whose record is garbage, or a link, never breaks status: the name still says."""
    queue = Queue(lock_dir)
    with queue.ticket(["my", "test"]) as ticket:
        assert ticket is not None
        (waiter,) = queue.waiters()
        assert (waiter.pid, waiter.command, waiter.position) == (os.getpid(), "my test", 1)
        # Someone replaces the record with a link to a secret: read as a regular file only.
        path = queue.path / ticket.name
        os.unlink(path)
        os.symlink("/etc/shadow", path)
        assert queue.waiters() == []  # a link is no live ticket: not locked by anyone
    assert queue.waiters() == []


# -- a queue folder planted in the lock directory ----------------------------------------------


def test_a_queue_symlink_is_never_followed(
    lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    """Every run looks into the queue; through a link it would unlink a victim's *.ticket files."""
    (first,) = pick_ids(1)
    victim = tmp_path / "victim"
    victim.mkdir()
    plant_file(victim / "precious.ticket", os.getuid(), 0o644)
    (lock_dir / "queue").symlink_to(victim)
    before = tree(victim)

    result = run_timed(["run", "--", "sh", "-c", PRINT_ID], shared_env(env, lock_dir, first))
    assert granted_id(result) == first
    assert tree(victim) == before


def test_a_queue_planted_as_a_file_does_not_deny_a_waiting_runner(
    lock_dir: Path, env: dict[str, str], children: Children
) -> None:
    """A runner that has to wait must still get the ID when it frees up."""
    (first,) = pick_ids(1)
    plant_file(lock_dir / "queue", NOBODY, 0o644)
    before = snapshot(lock_dir / "queue")
    reservation = DomainCoordinator(lock_dir, (first,)).try_reserve(["holder"])
    assert reservation is not None
    try:
        waiter = children.start(
            [CLI, "run", "--wait-timeout", "30", "--", "sh", "-c", PRINT_ID],
            env=shared_env(env, lock_dir, first),
        )
        # It says once that it queues in a folder of its own, naming the planted path.
        note = children.first_line(waiter)
        assert f"shared queue folder {lock_dir / 'queue'} is unusable" in note, note
        assert "waiting for a free ROS_DOMAIN_ID" in children.first_line(waiter)
    finally:
        reservation.release()
    stdout, stderr = waiter.communicate(timeout=DEADLINE)
    assert waiter.returncode == 0, stdout + stderr
    assert f"id={first}" in stdout
    assert snapshot(lock_dir / "queue") == before
