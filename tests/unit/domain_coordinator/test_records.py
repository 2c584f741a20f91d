"""``records``: the holder record, left beside an ID's lock for ``status``, and read back safely.

A reservation writes its record (who, what command, since when, which host; mode 0644)
and removes it on release; where another user planted a file at its path, a record of a
name of our own takes its place, so a holder that dies still leaves its trace.

The lock directory is writable by every user, so a record read back is untrusted: only
valid records are kept (a PID below pid_max, a time from 1970 to 9999, text fields),
newest first, their text made display-safe. The end-to-end tests plant one hostile
record while a real runner holds the ID and another real runner queues for it:
``status``, ``status --json`` and the queued runner's wait message all read it, and the
queued runner must still get the ID once it is free.
"""

from __future__ import annotations

import json
import os
import pwd
import signal
import socket
import stat
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import HUNG, run_cli, start_cli
from helpers.coordinator import status_rows
from helpers.domains import free_ids
from helpers.processes import poll_until

from ros_isolated_test.domain_coordinator import DomainCoordinator, domain_uses, records
from ros_isolated_test.domain_coordinator.escaped import died_holding
from ros_isolated_test.domain_coordinator.records import record_path

#: A user ID nobody has here: the record looks planted by another user.
PLANTER = 4242
FORGED = "FORGED-LINE"
WAITING = "waiting for a free ROS_DOMAIN_ID"


def test_holder_record_is_written_then_removed(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    before = time.time()
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["my_test", "--flag"]) as reservation:
        record = reservation.record
        assert record == lock_dir / f"domain-{domain_id}.uid{os.getuid()}.holder.json"
        data = json.loads(record.read_text(encoding="utf-8"))
        assert data["domain_id"] == domain_id
        assert data["pid"] == os.getpid()
        assert data["user"] == pwd.getpwuid(os.getuid()).pw_name
        assert data["command"] == "my_test --flag"
        assert before <= data["started"] <= time.time()
        assert data["host"] == socket.gethostname()
        assert stat.S_IMODE(record.stat().st_mode) == 0o644
        (held,) = domain_uses(lock_dir, (domain_id,))
        assert held.via == "lock"
        assert held.holder is not None
        assert held.holder.pid == os.getpid()
    assert not record.exists()
    assert not list(lock_dir.glob("*.json"))
    assert not list(lock_dir.glob(".*.tmp"))


@capabilities.ROOT
def test_a_file_planted_at_the_record_path_leaves_a_record_of_our_own_name(lock_dir: Path) -> None:
    """Should this holder die, a record of its own still says it held the ID."""
    (domain_id,) = free_ids(1)
    lock_dir.mkdir(exist_ok=True)
    planted = record_path(lock_dir, domain_id)
    planted.write_text("planted")
    os.chown(planted, 4242, 4242)
    os.utime(planted, (1000.0, 1000.0))
    reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"])
    assert reservation is not None and reservation.record is not None
    assert reservation.record != planted
    assert reservation.record.name.endswith(".holder.json")
    assert reservation.record.stat().st_uid == os.getuid()
    # Dying now (the descriptors closed, nothing removed): the next holder looks.
    reservation.port.close()
    if reservation.lock_fd is not None:
        os.close(reservation.lock_fd)
    assert died_holding(lock_dir, domain_id)
    # The control: a holder that releases removes its own record; the planted one stays.
    again = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"])
    assert again is not None and again.record is not None
    again_record = again.record
    again.release()
    assert not again_record.exists() and planted.exists()


def test_only_valid_records_of_the_id_are_read_newest_first(lock_dir: Path) -> None:
    """What ``status`` names: each valid record, the newest first, display-safe.

    Anything else at a record's name (another ID's record, a PID that is no int, a time
    before 1970, a command that is no text, no object at all) is skipped; the two valid
    records are the control that the others were read too.
    """
    valid = {"domain_id": 7, "pid": 100, "user": "u", "command": "old", "started": 1000.0}

    def plant(uid: int, data: object) -> None:
        record_path(lock_dir, 7, uid).write_text(json.dumps(data))

    plant(1001, valid)
    plant(1002, {**valid, "pid": 101, "command": "new\x1b[2K", "started": 2000.0})
    plant(1003, {**valid, "domain_id": 8})
    plant(1004, {**valid, "pid": True})
    plant(1005, {**valid, "started": 0})
    plant(1006, {**valid, "command": ["not", "text"]})
    plant(1007, [7, 100])
    found = records.read_records(lock_dir, 7)
    assert [(holder.pid, holder.command) for holder in found] == [
        (101, "new\\x1b[2K"),
        (100, "old"),
    ]
    assert records.read_records(lock_dir, 8) == []  # none at ID 8's names


# -- planted records, read by status and a waiting runner ---------------------------------------


def _huge() -> bytes:
    """A valid record whose command alone is bigger than any record a runner reads."""
    return b'{"domain_id": %d, "pid": 1, "user": "u", "command": "' + b"x" * 200_000 + b'"}'


#: name -> record bytes (``%d`` is the domain ID). Each crashed status or a waiter, or
#: forged a line, before records were validated.
HOSTILE = {
    "pid 1e400": b'{"domain_id": %d, "pid": 1e400, "user": "u", "command": "c", "started": 1}',
    "started 1e300": b'{"domain_id": %d, "pid": 1, "user": "u", "command": "c", "started": 1e300}',
    "started NaN": b'{"domain_id": %d, "pid": 1, "user": "u", "command": "c", "started": NaN}',
    # Newer than the real record: shown instead of it, were it not refused.
    "pid beyond pid_max": (
        b'{"domain_id": %d, "pid": 99999999999999999999, "user": "u", "command": "c", '
        b'"started": 4000000000}'
    ),
    "domain_id 1e400": b'{"domain_id": 1e400, "pid": 1, "user": "u", "command": "c", "started": 1}',
    "not an object": b"[%d, 1, 2]",
    "deeply nested": b"[" * 60_000,
    "invalid UTF-8": (
        b'{"domain_id": %d, "pid": 1, "user": "\xff\xfe", "command": "c", "started": 1}'
    ),
    "huge": _huge(),
}


class Scene:
    """A real runner holding the pool's one ID, and a real runner queued for it."""

    def __init__(self, env: dict[str, str], tmp_path: Path) -> None:
        self.env = env
        self.tmp_path = tmp_path
        self.lock_dir = Path(env["ROS_ISOLATED_TEST_LOCK_DIR"])
        self.domain_id = int(env["ROS_ISOLATED_TEST_DOMAINS"])
        self.processes: list[subprocess.Popen[bytes]] = []
        self.holder = self._start(["run", "--", "sleep", "120"], "holder.log")
        poll_until(
            lambda: any(row.get("pid") == self.holder.pid for row in self.rows()),
            "the holder never held the ID",
        )

    def _start(self, args: list[str], log: str) -> subprocess.Popen[bytes]:
        return start_cli(args, self.env, self.tmp_path / log, self.processes)

    def rows(self) -> list[dict[str, object]]:
        return status_rows(self.env)

    def queue(self) -> subprocess.Popen[bytes]:
        """Start the waiter; returns once it printed its wait message (which reads records)."""
        self.waiter = self._start(
            ["run", "--wait-timeout", "120", "--", "echo", "waiter-marker"], "waiter.log"
        )

        def waiting() -> bool:
            assert self.waiter.poll() is None, self.waiter_log()
            return WAITING in self.waiter_log()

        poll_until(waiting, "the waiter never said it waits")
        return self.waiter

    def waiter_log(self) -> str:
        return (self.tmp_path / "waiter.log").read_text(errors="replace")

    def release(self) -> None:
        """The holder ends: the waiter gets the ID, runs its test and exits 0."""
        self.holder.send_signal(signal.SIGTERM)
        assert self.waiter.wait(HUNG) == 0, self.waiter_log()
        assert "waiter-marker" in self.waiter_log()

    def stop(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.kill()
            process.wait(HUNG)


@pytest.fixture
def scene(one_id: dict[str, str], tmp_path: Path) -> Iterator[Scene]:
    held = Scene(one_id, tmp_path)
    yield held
    held.stop()


def _plant(scene: Scene, content: bytes) -> Path:
    path = records.record_path(scene.lock_dir, scene.domain_id, PLANTER)
    path.write_bytes(content.replace(b"%d", str(scene.domain_id).encode()))
    return path


def _status_shows_the_real_holder(scene: Scene) -> None:
    table = run_cli(["status"], scene.env)
    assert table.returncode == 0, table.stdout + table.stderr
    (line,) = [
        item for item in table.stdout.splitlines() if item.split()[:1] == [str(scene.domain_id)]
    ]
    assert f" {scene.holder.pid} " in line, table.stdout
    assert "sleep 120" in line, table.stdout
    rows = [row for row in scene.rows() if row["via"] == "lock"]
    assert [(row["pid"], row["command"]) for row in rows] == [(scene.holder.pid, "sleep 120")]


def test_a_genuine_record_is_shown_with_its_pid_and_command(scene: Scene) -> None:
    """Positive control: nothing planted, the holder and its command are what status shows."""
    _status_shows_the_real_holder(scene)
    scene.queue()
    assert f"pid {scene.holder.pid} " in scene.waiter_log()
    _status_shows_the_real_holder(scene)
    scene.release()


@pytest.mark.parametrize("variant", sorted(HOSTILE))
def test_a_planted_record_breaks_neither_status_nor_a_waiting_runner(
    scene: Scene, variant: str
) -> None:
    _plant(scene, HOSTILE[variant])
    _status_shows_the_real_holder(scene)
    scene.queue()
    assert "Traceback" not in scene.waiter_log(), scene.waiter_log()
    _status_shows_the_real_holder(scene)
    scene.release()


def test_a_planted_command_forges_no_line_in_status_or_the_wait_message(scene: Scene) -> None:
    """Control characters are shown escaped, on the one line of the record they came in."""
    forged = f"c\r\n{scene.domain_id}  runner   4242  root  {FORGED}\x1b[2K\x1b]0;title\x07"
    record = {
        "domain_id": scene.domain_id,
        "pid": 4242,
        "user": "root\nroot",
        "command": forged,
        "started": time.time() + 3600,  # the newest record: the one status shows
        "host": "h\rh",
    }
    _plant(scene, json.dumps(record).encode())
    scene.queue()
    table = run_cli(["status"], scene.env)
    assert table.returncode == 0, table.stdout + table.stderr
    for output in (table.stdout, scene.waiter_log()):
        assert "\r" not in output and "\x1b" not in output and "\x07" not in output, output
        lines = [line for line in output.splitlines() if FORGED in line]
        assert lines, output  # it is shown, on the line of its record, escaped
        assert all("c\\x0d\\x0a" in line for line in lines), lines
    (row,) = [row for row in scene.rows() if row["via"] == "lock"]
    assert row["pid"] == 4242
    assert row["command"] == forged.replace("\r", "\\x0d").replace("\n", "\\x0a").replace(
        "\x1b", "\\x1b"
    ).replace("\x07", "\\x07")
    assert (row["user"], row["host"]) == ("root\\x0aroot", "h\\x0dh")
    scene.release()


def test_user_name_is_the_passwd_name_or_the_number_or_unknown() -> None:
    """One lookup for records, tickets, squatters and survivors, never an exception."""
    assert records.user_name(os.getuid()) == pwd.getpwuid(os.getuid()).pw_name
    with pytest.raises(KeyError):
        pwd.getpwuid(PLANTER)  # the control: nobody has this UID here
    assert records.user_name(PLANTER) == str(PLANTER)
    assert records.user_name(None) == "?"  # a process gone before its owner was read
