"""``status`` lists runners queued for an ID, not only the IDs held: real holder, real waiter."""

from __future__ import annotations

import getpass
import json
import os
import pwd
import signal
import subprocess
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import HUNG, run_cli, start_cli
from helpers.processes import poll_until

from ros_isolated_test.domain_coordinator.queue import Queue

#: A user ID nobody has here.
UNNAMED = 4242


def _rows(env: dict[str, str]) -> list[dict[str, object]]:
    listed = run_cli(["status", "--json"], env)
    assert listed.returncode == 0, listed.stderr
    rows: list[dict[str, object]] = json.loads(listed.stdout)
    return rows


def test_status_lists_a_waiting_runner_with_its_pid_user_command_and_place(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    holder = start_cli(["run", "--", "sleep", "60"], one_id, tmp_path / "holder.log", started)
    poll_until(
        lambda: any(row.get("pid") == holder.pid for row in _rows(one_id)),
        "the holder never held the ID",
    )
    # Control: one runner holds, nobody waits.
    assert [row for row in _rows(one_id) if row["via"] == "queue"] == []
    assert "Waiting for a domain ID" not in run_cli(["status"], one_id).stdout

    waiter = start_cli(
        ["run", "--wait-timeout", "120", "--", "echo", "waiter-marker"],
        one_id,
        tmp_path / "waiter.log",
        started,
    )

    def queued() -> list[dict[str, object]]:
        assert waiter.poll() is None, (tmp_path / "waiter.log").read_text()
        return [row for row in _rows(one_id) if row["via"] == "queue"]

    poll_until(lambda: bool(queued()), "the waiting runner never showed in status --json")
    (row,) = queued()
    assert row["pid"] == waiter.pid
    assert row["position"] == 1
    assert row["domain_id"] is None
    assert row["user"] == getpass.getuser()
    assert "echo waiter-marker" in str(row["command"])
    assert isinstance(row["started"], float) and row["started"] <= time.time()
    held = [row for row in _rows(one_id) if row["via"] == "lock"]
    assert [item["pid"] for item in held] == [holder.pid]  # held rows keep their shape

    table = run_cli(["status"], one_id).stdout
    assert "Waiting for a domain ID" in table, table
    waiting = table.split("Waiting for a domain ID", 1)[1].splitlines()
    line = next(item for item in waiting if f" {waiter.pid} " in item)
    assert line.split()[0] == "1"
    assert "echo waiter-marker" in line

    # The holder ends: the waiter gets the ID, runs, and leaves the queue.
    holder.send_signal(signal.SIGTERM)
    assert waiter.wait(HUNG) == 0, (tmp_path / "waiter.log").read_text()
    assert "waiter-marker" in (tmp_path / "waiter.log").read_text()
    assert [row for row in _rows(one_id) if row["via"] == "queue"] == []


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


@capabilities.ROOT
def test_a_squatter_of_a_user_passwd_does_not_name_shows_its_uid(
    one_id: dict[str, str], started: list[subprocess.Popen[bytes]]
) -> None:
    """As a record or a ticket shows its user: the numeric UID (containers), not "?"."""
    with pytest.raises(KeyError):
        pwd.getpwuid(UNNAMED)  # the control: nobody has this UID here
    domain_id = one_id["ROS_ISOLATED_TEST_DOMAINS"]
    squatter = subprocess.Popen(["sleep", "600"], env={"ROS_DOMAIN_ID": domain_id}, user=UNNAMED)
    started.append(squatter)
    (row,) = [row for row in _rows(one_id) if row["pid"] == squatter.pid]
    assert (row["via"], row["domain_id"], row["user"]) == ("environment", int(domain_id), "4242")


def test_status_shows_the_gazebo_partition_a_held_run_gave_its_test(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """Rebuilt from the holder record (host, ID, PID): the very name the test has."""
    seen = tmp_path / "seen"
    script = f'echo "$GZ_PARTITION" > {seen}.tmp && mv {seen}.tmp {seen} && sleep 60'
    holder = start_cli(["run", "--", "sh", "-c", script], one_id, tmp_path / "h.log", started)
    poll_until(seen.exists, "the held test never started")
    name = seen.read_text().strip()
    assert name.startswith("rit_"), name  # the control: the test has a partition
    (row,) = [row for row in _rows(one_id) if row.get("pid") == holder.pid]
    assert row["via"] == "lock"
    assert row["gz_partition"] == name
    table = run_cli(["status"], one_id).stdout
    assert "GZ_PARTITION" in table.splitlines()[0], table
    (line,) = [line for line in table.splitlines() if f" {holder.pid} " in line]
    assert f" {name} " in line, table
