"""Planted holder records never break ``status`` or a waiting runner, nor forge a line.

The lock directory is writable by every user, so a holder record read back is untrusted.
Each test plants one hostile record while a real runner holds the ID and another real
runner queues for it: ``status``, ``status --json`` and the queued runner's wait message
all read it, and the queued runner must still get the ID once it is free.
"""

from __future__ import annotations

import json
import os
import pwd
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers.commands import CLI, HUNG, run_cli
from helpers.processes import poll_until

from ros_isolated_test.domain_coordinator import holder

#: A user ID nobody has here: the record looks planted by another user.
PLANTER = 4242
FORGED = "FORGED-LINE"
WAITING = "waiting for a free ROS_DOMAIN_ID"


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
        with (self.tmp_path / log).open("wb") as out:
            process = subprocess.Popen(
                [CLI, *args], env=self.env, stdin=subprocess.DEVNULL, stdout=out, stderr=out
            )
        self.processes.append(process)
        return process

    def rows(self) -> list[dict[str, object]]:
        listed = run_cli(["status", "--json"], self.env)
        assert listed.returncode == 0, listed.stdout + listed.stderr
        rows: list[dict[str, object]] = json.loads(listed.stdout)
        return rows

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
    path = holder.record_path(scene.lock_dir, scene.domain_id, PLANTER)
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
    assert holder.user_name(os.getuid()) == pwd.getpwuid(os.getuid()).pw_name
    with pytest.raises(KeyError):
        pwd.getpwuid(PLANTER)  # the control: nobody has this UID here
    assert holder.user_name(PLANTER) == str(PLANTER)
    assert holder.user_name(None) == "?"  # a process gone before its owner was read
