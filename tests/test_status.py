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
from helpers.domains import free_ids
from helpers.processes import poll_until, user_keywords
from helpers.survivors import alive_with, build_setuid_helper, tagged

from ros_isolated_test.domain_coordinator.queue import Queue

#: A user ID nobody has here.
UNNAMED = 4242
NOBODY = 65534


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


def _lines_naming(text: str, pid: int) -> list[list[str]]:
    """The ``status`` table rows (split in words) whose PID column is ``pid``."""
    return [line.split() for line in text.splitlines() if line.split()[2:3] == [str(pid)]]


@capabilities.SETUID_HELPER
def test_a_survivor_is_listed_once_as_a_survivor_and_a_plain_squatter_as_a_squatter(
    traversable_dir: Path, env: dict[str, str], started: list[subprocess.Popen[bytes]]
) -> None:
    """A survivor still has the ID in ROS_DOMAIN_ID, so the squatter scan found it as well:
    ``status``, the waiting line and the refusal named the same PID as squatter and as
    survivor. The control, beside it on the same ID: a plain process with ROS_DOMAIN_ID
    set (never a test) is still a squatter."""
    helper = build_setuid_helper(traversable_dir)
    locks = traversable_dir / "locks"
    locks.mkdir()
    os.chmod(locks, 0o1777)
    (domain_id,) = free_ids(1)
    runner_env = {
        **env,
        "ROS_ISOLATED_TEST_LOCK_DIR": str(locks),
        "ROS_ISOLATED_TEST_DOMAINS": str(domain_id),
        "HOME": "/nonexistent",
        "USER": "nobody",
    }
    with tagged() as tag:
        # A runner run as nobody cannot end its test's setuid-root child: a real survivor,
        # which keeps the ROS_DOMAIN_ID its runner gave it.
        done = run_cli(
            ["run", "--kill-grace", "0.5", "--", str(helper), tag],
            runner_env,
            **user_keywords(NOBODY),
        )
        assert done.returncode == 0, done.stdout + done.stderr
        (survivor,) = alive_with(tag)
        assert f"stays blocked while {survivor} (setuid_helper)" in done.stdout, done.stdout
        environ = Path(f"/proc/{survivor}/environ").read_bytes().split(b"\0")
        assert f"ROS_DOMAIN_ID={domain_id}".encode() in environ
        squatter = subprocess.Popen(
            ["sleep", tag], env={"ROS_DOMAIN_ID": str(domain_id)}, cwd=traversable_dir
        )
        started.append(squatter)

        rows = [row for row in _rows(runner_env) if row["domain_id"] == domain_id]
        survivor_rows = [row["via"] for row in rows if row.get("pid") == survivor]
        squatter_rows = [row["via"] for row in rows if row.get("pid") == squatter.pid]
        assert (survivor_rows, squatter_rows) == (["survivor"], ["environment"]), rows

        table = run_cli(["status"], runner_env).stdout
        assert [words[:2] for words in _lines_naming(table, survivor)] == [
            [str(domain_id), "survivor"]
        ], table
        assert [words[:2] for words in _lines_naming(table, squatter.pid)] == [
            [str(domain_id), "squatter"]
        ], table

        # The waiting line and the refusal name who holds the pool: each process once.
        waiter = start_cli(
            ["run", "--wait-timeout", "120", "--", "true"],
            runner_env,
            traversable_dir / "waiter.log",
            started,
        )
        log = traversable_dir / "waiter.log"
        poll_until(lambda: "waiting for a free ROS_DOMAIN_ID" in log.read_text(), "no waiting")
        refused = run_cli(["run", "--wait-timeout", "0", "--", "true"], runner_env)
        assert refused.returncode == 3, refused.stdout + refused.stderr
        (waiting,) = [line for line in log.read_text().splitlines() if "waiting for" in line]
        for said in (waiting, refused.stdout + refused.stderr):
            assert said.count(f"pid {survivor} ") == 1, said
            assert f"{domain_id}: survivor pid {survivor} (root)" in said, said
            assert f"{domain_id}: squatter pid {squatter.pid} " in said, said
    # Once the survivor is gone, the waiter gets the ID (a clean release: squatters of it
    # do not block it).
    assert waiter.wait(HUNG) == 0, log.read_text()
    assert f"Running with ROS_DOMAIN_ID {domain_id}" in log.read_text()
