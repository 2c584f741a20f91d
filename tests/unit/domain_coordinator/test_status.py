"""``status``: every domain ID in use on this machine, by what, and who waits, read once.

An ID is in use when a runner holds its lock (in any pool: other users' runners may use
pools of their own), when something binds its TCP port (upstream's coordinator, even
before any runner made the lock directory), when a DDS participant binds its UDP ports,
when a process carries it in ROS_DOMAIN_ID (a squatter; a runner's own test is none),
or while a survivor of its last test lives: listed once, as a survivor. Runners queued
for an ID are listed apart, in their order. Real holders, waiters, squatters and
survivors throughout; how the table draws it: ``unit/cli/test_status_table``.
"""

from __future__ import annotations

import getpass
import os
import pwd
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import HUNG, ament_args, run_cli, start_cli
from helpers.coordinator import (
    UPSTREAM_SCRIPT,
    WAIT_SCRIPT,
    stand_in_colcon,
    status_rows,
    wait_for_environment,
    without_domain_id,
)
from helpers.domains import free_ids
from helpers.hostile_lock_dir import make_shared_lock_dir
from helpers.processes import Children, poll_until, user_keywords
from helpers.survivors import alive_with, build_setuid_helper, tagged

from ros_isolated_test.domain_coordinator import (
    LOCK_DIR_ENV,
    POOL_ENV,
    DomainCoordinator,
    DomainUse,
    domain_uses,
)
from ros_isolated_test.domain_coordinator.port_guard import claim_port

#: A user ID nobody has here.
UNNAMED = 4242
NOBODY = 65534


def test_status_lists_a_waiting_runner_with_its_pid_user_command_and_place(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    holder = start_cli(["run", "--", "sleep", "60"], one_id, tmp_path / "holder.log", started)
    poll_until(
        lambda: any(row.get("pid") == holder.pid for row in status_rows(one_id)),
        "the holder never held the ID",
    )
    # Control: one runner holds, nobody waits.
    assert [row for row in status_rows(one_id) if row["via"] == "queue"] == []
    assert "Waiting for a domain ID" not in run_cli(["status"], one_id).stdout

    waiter = start_cli(
        ["run", "--wait-timeout", "120", "--", "echo", "waiter-marker"],
        one_id,
        tmp_path / "waiter.log",
        started,
    )

    def queued() -> list[dict[str, object]]:
        assert waiter.poll() is None, (tmp_path / "waiter.log").read_text()
        return [row for row in status_rows(one_id) if row["via"] == "queue"]

    poll_until(lambda: bool(queued()), "the waiting runner never showed in status --json")
    (row,) = queued()
    assert row["pid"] == waiter.pid
    assert row["position"] == 1
    assert row["domain_id"] is None
    assert row["user"] == getpass.getuser()
    assert "echo waiter-marker" in str(row["command"])
    assert isinstance(row["started"], float) and row["started"] <= time.time()
    held = [row for row in status_rows(one_id) if row["via"] == "lock"]
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
    assert [row for row in status_rows(one_id) if row["via"] == "queue"] == []


def test_status_lists_an_id_held_outside_the_callers_pool(
    lock_dir: Path, env: dict[str, str]
) -> None:
    """Another user's runner may have a pool of its own; its IDs are still held here."""
    (domain_id,) = free_ids(1)
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["other_pool_test"]):
        listed = status_rows(env)  # the default pool, 1-101
    rows = [row for row in listed if row["via"] == "lock"]
    assert [(row["domain_id"], row["pid"]) for row in rows] == [(domain_id, os.getpid())]


def test_status_lists_upstream_holders_before_any_runner_made_the_lock_dir(
    lock_dir: Path, env: dict[str, str], children: Children
) -> None:
    # Upstream's first free ID, and no squatter's (upstream does not look): status must
    # name upstream's port alone.
    upstream = children.python(UPSTREAM_SCRIPT, *free_ids(1, range(1, 101)))
    upstream_id = int(children.first_line(upstream))
    missing = lock_dir / "not-made-yet"
    assert domain_uses(missing, (upstream_id,)) == [DomainUse(upstream_id, "port", None)]
    env[LOCK_DIR_ENV] = str(missing)
    env[POOL_ENV] = str(upstream_id)
    assert status_rows(env) == [{"domain_id": upstream_id, "via": "port"}]
    assert not missing.exists()


def test_a_holders_own_test_is_no_squatter_but_a_strangers_process_is(
    lock_dir: Path, children: Children
) -> None:
    """The holder's test carries the ID in ROS_DOMAIN_ID too: it is the holder's, not listed.

    The control, on the same ID at the same time: a process no holder started (orphaned,
    its parent shell gone) with the same variable is listed as a squatter.
    """
    (domain_id,) = free_ids(1)
    env = {**without_domain_id(), "ROS_DOMAIN_ID": str(domain_id)}
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["holder"]):
        own_test = children.start(["sleep", "600"], env=env)
        wait_for_environment(own_test.pid, domain_id)
        orphan = subprocess.run(
            ["sh", "-c", "sleep 600 >/dev/null 2>&1 & echo $!"],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
        stranger = int(orphan.stdout)
        try:
            wait_for_environment(stranger, domain_id)
            uses = domain_uses(lock_dir, (domain_id,))
        finally:
            os.kill(stranger, signal.SIGKILL)
    named = [(use.via, use.holder.pid if use.holder else None) for use in uses]
    assert named == [("lock", os.getpid()), ("environment", stranger)]


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
    (row,) = [row for row in status_rows(one_id) if row["pid"] == squatter.pid]
    assert (row["via"], row["domain_id"], row["user"]) == ("environment", int(domain_id), "4242")


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
    locks = make_shared_lock_dir(traversable_dir)
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

        rows = [row for row in status_rows(runner_env) if row["domain_id"] == domain_id]
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


@pytest.mark.ros
@capabilities.UPSTREAM_RUNNER
def test_a_test_of_upstreams_runner_is_upstreams_not_a_squatter(
    lock_dir: Path, env: dict[str, str], children: Children, tmp_path: Path
) -> None:
    """Jazzy's run_test_isolated.py, real, holds the ID's port and set the ID for its
    test: the ID is upstream's, named by the runner's process; its test is no squatter.

    The control, at the same time: a process on another ID whose port an unrelated
    program holds is still a squatter beside the port, not upstream's.
    """
    runner = str(capabilities.UPSTREAM_RUNNER_PATH)
    args = ament_args(tmp_path / "r.xml", ["sh", "-c", WAIT_SCRIPT])
    upstream_runner = children.start([sys.executable, "-u", runner, *args], env=env)
    line = children.first_line(upstream_runner)
    while not line.startswith("pid="):
        line = children.first_line(upstream_runner)
    test_pid, domain_id = (int(part.split("=", 1)[1]) for part in line.split())
    wait_for_environment(test_pid, domain_id)
    (other_id,) = free_ids(1, [i for i in range(1, 233) if i != domain_id])
    port = claim_port(other_id)
    assert port is not None
    try:
        squatter = children.start(
            ["sh", "-c", WAIT_SCRIPT], env={**env, "ROS_DOMAIN_ID": str(other_id)}
        )
        wait_for_environment(squatter.pid, other_id)
        uses = domain_uses(lock_dir, (domain_id, other_id))
        env[POOL_ENV] = f"{domain_id},{other_id}"
        table = run_cli(["status"], env).stdout
    finally:
        port.close()
    # Only what this test started: the machine may run other work on these IDs (a busy
    # machine's squatter where upstream's coordinator, counting from 1, landed).
    ours = {upstream_runner.pid, test_pid, squatter.pid}
    named = [
        (use.domain_id, use.via, use.holder.pid if use.holder else None)
        for use in uses
        if use.holder is None or use.holder.pid in ours
    ]
    assert named == [
        (domain_id, "upstream", upstream_runner.pid),
        (other_id, "port", None),
        (other_id, "environment", squatter.pid),
    ]
    upstreams = [use for use in uses if use.via == "upstream"]
    assert upstreams and upstreams[0].holder is not None
    assert "run_test_isolated.py" in upstreams[0].holder.command
    lines = table.splitlines()[1:]
    rows = [
        tuple(line.split()[:2])
        for line in lines
        if "port" in line.split()[:2] or any(str(pid) in line.split() for pid in ours)
    ]
    assert rows == [
        (str(domain_id), "upstream"),
        (str(other_id), "port"),
        (str(other_id), "squatter"),
    ], table


@capabilities.SOCK_DIAG_BOUND
def test_colcon_is_named_only_for_an_id_whose_port_colcon_itself_holds(
    lock_dir: Path, children: Children, tmp_path: Path
) -> None:
    """Two colcon stand-ins, each having set an ID for its task: the one holding the port
    itself (as its coordinator does) is named colcon's; the other, whose ID's port another
    process holds (an environment hook's ID, a runner of ours on it), is not: the port
    is listed as taken and its task as a squatter."""
    coordinated, hooked = free_ids(2)
    colcon = stand_in_colcon(tmp_path)
    env = without_domain_id()
    env.pop("COLCON_EXTENSION_BLOCKLIST", None)
    tasks: dict[int, tuple[int, int]] = {}  # ID -> (colcon, its task)
    for domain_id, hold in ((coordinated, "hold"), (hooked, "free")):
        argv = [sys.executable, str(colcon), str(domain_id), hold, "sh", "-c", WAIT_SCRIPT]
        process = children.start(argv, env=env)
        pid = int(children.first_line(process).split()[0].removeprefix("pid="))
        wait_for_environment(pid, domain_id)
        tasks[domain_id] = (process.pid, pid)
    port = claim_port(hooked)
    assert port is not None
    try:
        uses = domain_uses(lock_dir, (coordinated, hooked))
    finally:
        port.close()
    ours = {pid for pair in tasks.values() for pid in pair}
    named = [
        (use.domain_id, use.via, use.holder.pid if use.holder else None)
        for use in uses
        if use.holder is None or use.holder.pid in ours
    ]
    assert sorted(named, key=str) == sorted(
        [
            (coordinated, "colcon", tasks[coordinated][0]),
            (hooked, "port", None),
            (hooked, "environment", tasks[hooked][1]),
        ],
        key=str,
    )
