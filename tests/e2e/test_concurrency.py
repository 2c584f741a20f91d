"""Acceptance: 50 runners started at once hold 50 distinct non-zero IDs at the same time."""

from __future__ import annotations

import getpass
import json
import os
import re
import socket
import stat
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import pytest
from helpers.commands import CLI, run_cli
from helpers.coordinator import STATUS_COLUMNS
from helpers.domains import free_ids

from ros_isolated_test.domain_coordinator import LOCK_DIR_ENV, POOL_ENV
from ros_isolated_test.domain_coordinator.port_guard import claim_port

RUNNERS = 50
#: Only stops a hung test: 50 runners start in about 15 s on a quiet machine of 2 cores.
DEADLINE = 120.0

#: The test command: write ROS_DOMAIN_ID, the runner's PID and its own, then wait until
#: every runner's test has written (all IDs held at once), then until the parent says go.
HOLDER = """\
import os, sys, time
from pathlib import Path

ids_dir, index, count, go = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3]), Path(sys.argv[4])
temp = ids_dir / f".{index}.tmp"
temp.write_text(f"{os.environ['ROS_DOMAIN_ID']} {os.getppid()} {os.getpid()}")
temp.rename(ids_dir / f"{index}.id")
deadline = time.monotonic() + 240  # longer than the parent waits: it reports first
while sum(name.endswith(".id") for name in os.listdir(ids_dir)) < count:
    if time.monotonic() > deadline:
        sys.exit(f"barrier: not all {count} tests held an ID at once")
    time.sleep(0.05)
while not go.exists():
    if time.monotonic() > deadline:
        sys.exit("the parent never said go")
    time.sleep(0.05)
"""


@dataclass
class Runner:
    index: int
    process: subprocess.Popen[bytes]
    log: Path
    command: list[str]


@dataclass(frozen=True)
class Seen:
    """What one test command wrote while it ran."""

    domain_id: int
    runner_pid: int
    test_pid: int


class Crowd:
    """RUNNERS ``ros-isolated-test run`` processes, started back to back."""

    def __init__(self, tmp_path: Path, env: dict[str, str]) -> None:
        self.ids_dir = tmp_path / "ids"
        self.ids_dir.mkdir()
        self.go = tmp_path / "go"
        self.script = tmp_path / "holder.py"
        self.script.write_text(HOLDER)
        self.logs = tmp_path / "logs"
        self.logs.mkdir()
        self.env = env
        self.runners: list[Runner] = []
        self._handles: list[IO[bytes]] = []

    def start(self) -> None:
        for index in range(RUNNERS):
            command = [
                sys.executable,
                str(self.script),
                str(self.ids_dir),
                str(index),
                str(RUNNERS),
                str(self.go),
            ]
            log = self.logs / f"{index}.log"
            handle = open(log, "wb")  # noqa: SIM115 - closed in stop()
            self._handles.append(handle)
            process = subprocess.Popen(
                [CLI, "run", "--", *command],
                env=self.env,
                stdin=subprocess.DEVNULL,
                stdout=handle,
                stderr=subprocess.STDOUT,
            )
            self.runners.append(Runner(index, process, log, command))

    def wait_until_all_hold(self) -> dict[int, Seen]:
        deadline = time.monotonic() + DEADLINE
        while True:
            written = sorted(self.ids_dir.glob("*.id"))
            if len(written) == RUNNERS:
                break
            ended = [runner for runner in self.runners if runner.process.poll() is not None]
            if ended:
                runner = ended[0]
                pytest.fail(
                    f"runner {runner.index} ended early with {runner.process.returncode}:\n"
                    + runner.log.read_text(errors="replace")
                )
            if time.monotonic() > deadline:
                pytest.fail(f"only {len(written)} of {RUNNERS} tests started in {DEADLINE} s")
            time.sleep(0.05)
        seen: dict[int, Seen] = {}
        for path in written:
            domain_id, runner_pid, test_pid = map(int, path.read_text().split())
            seen[int(path.stem)] = Seen(domain_id, runner_pid, test_pid)
        return seen

    def release(self) -> list[int]:
        self.go.touch()
        deadline = time.monotonic() + DEADLINE
        codes = []
        for runner in self.runners:
            remaining = max(0.1, deadline - time.monotonic())
            codes.append(runner.process.wait(timeout=remaining))
        return codes

    def stop(self) -> None:
        self.go.touch()
        for runner in self.runners:
            if runner.process.poll() is None:
                try:
                    runner.process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    runner.process.kill()
                    runner.process.wait()
        for handle in self._handles:
            handle.close()


@pytest.fixture
def crowd(tmp_path: Path, env: dict[str, str], lock_dir: Path) -> Iterator[Crowd]:
    # A lock dir none of them finds in place: all race to create it.
    env[LOCK_DIR_ENV] = str(lock_dir / "shared")
    crowd = Crowd(tmp_path, env)
    yield crowd
    crowd.stop()


def _listed_pids(stdout: str) -> dict[int, str]:
    """PID -> HELD BY of every row of the ``status`` table (ID, HELD BY, PID, ...).

    A "port" or "participant" row has no PID ("-"): a bound port does not say who binds it.
    """
    rows = [line.split() for line in stdout.splitlines()[1:] if line.strip()]
    anonymous = ("port", "participant")
    assert all(len(row) >= 6 and (row[2].isdigit() or row[1] in anonymous) for row in rows), stdout
    return {int(row[2]): row[1] for row in rows if row[2].isdigit()}


def _table_rows(stdout: str) -> dict[int, tuple[int, str, str, str]]:
    """The rows of runners; ports and squatters elsewhere on this machine are skipped."""
    rows = {}
    for line in stdout.splitlines()[1:]:
        match = re.match(r"^\s*(\d+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(.*)$", line)
        assert match, f"unexpected status line: {line!r}"
        domain_id, kind, pid, user, started, _gz_partition, command = match.groups()
        if kind != "runner":
            continue
        rows[int(domain_id)] = (int(pid), user, started, command)
    return rows


def test_fifty_runners_at_once_hold_fifty_distinct_ids(crowd: Crowd, env: dict[str, str]) -> None:
    started_at = time.time()
    begin = time.monotonic()
    crowd.start()
    seen = crowd.wait_until_all_hold()
    # Every test command has written, and none may exit before all have: all 50 held at once.
    by_runner = {runner.index: runner for runner in crowd.runners}
    ids = [item.domain_id for item in seen.values()]
    assert len(set(ids)) == RUNNERS, sorted(ids)
    assert all(1 <= domain_id <= 101 for domain_id in ids), sorted(ids)
    for index, item in seen.items():
        assert item.runner_pid == by_runner[index].process.pid

    # While they hold: status names every one, with the runner's PID.
    status_env = crowd.env
    listed = run_cli(["status", "--json"], status_env)
    checked_at = time.time()
    assert listed.returncode == 0, listed.stderr
    rows = [row for row in json.loads(listed.stdout) if row["via"] == "lock"]
    assert len(rows) == RUNNERS
    by_id = {row["domain_id"]: row for row in rows}
    assert set(by_id) == set(ids)
    for index, item in seen.items():
        row = by_id[item.domain_id]
        runner = by_runner[index]
        assert row["pid"] == runner.process.pid
        assert row["user"] == getpass.getuser()
        assert row["command"] == " ".join(runner.command)
        assert started_at <= row["started"] <= checked_at
        assert row["host"] == socket.gethostname()

    table = run_cli(["status"], status_env)
    assert table.returncode == 0, table.stderr
    assert table.stdout.splitlines()[0].split() == STATUS_COLUMNS
    table_rows = _table_rows(table.stdout)
    # The control for the check after they end: while they hold, every runner's PID is seen.
    listed_while_held = _listed_pids(table.stdout)
    assert {item.runner_pid: "runner" for item in seen.values()}.items() <= (
        listed_while_held.items()
    ), table.stdout
    assert set(table_rows) == set(ids)
    for domain_id, row in by_id.items():
        pid, user, started, command = table_rows[domain_id]
        assert pid == row["pid"]
        assert user == row["user"][:10]
        assert started == time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(row["started"]))
        assert command == row["command"]

    # Then they end, and every one passed.
    codes = crowd.release()
    logs = {runner.index: runner.log.read_text(errors="replace") for runner in crowd.runners}
    failed = {index: logs[index] for index, code in enumerate(codes) if code != 0}
    assert not failed, failed
    for index, item in seen.items():
        assert f"Running with ROS_DOMAIN_ID {item.domain_id} (Gazebo partition " in logs[index]

    # Afterwards nothing is held in the lock dir they shared.
    lock_dir = Path(crowd.env[LOCK_DIR_ENV])
    assert stat.S_IMODE(lock_dir.stat().st_mode) == 0o1777
    assert len(list(lock_dir.glob("domain-*.lock"))) >= RUNNERS
    assert not list(lock_dir.glob("*.holder.json"))
    after = run_cli(["status", "--json"], status_env)
    assert after.returncode == 0, after.stderr
    assert [row for row in json.loads(after.stdout) if row["via"] == "lock"] == []
    # The plain table too; a process elsewhere on the machine that happens to carry one of
    # these IDs in ROS_DOMAIN_ID would be listed as a squatter, so look for lock rows only.
    used_only = {**status_env, POOL_ENV: ",".join(map(str, sorted(ids)))}
    plain = run_cli(["status"], used_only)
    assert plain.returncode == 0, plain.stderr
    theirs = {pid for item in seen.values() for pid in (item.runner_pid, item.test_pid)}
    listed_after = _listed_pids(plain.stdout)
    still = {pid: kind for pid, kind in listed_after.items() if pid in theirs or kind == "runner"}
    assert not still, plain.stdout
    # Either nothing at all, or the table: others on a busy machine may have taken some of
    # these IDs since (a port or a squatter, never one of our runners: checked above).
    if plain.stdout.startswith("No domain ID of the pool is held"):
        assert os.fspath(lock_dir) in plain.stdout
    else:
        assert plain.stdout.split()[:3] == ["ID", "HELD", "BY"], plain.stdout

    elapsed = time.monotonic() - begin
    print(f"{RUNNERS} runners: {elapsed:.1f} s")


def test_status_says_none_held_when_nothing_ran(env: dict[str, str], lock_dir: Path) -> None:
    # A pool of IDs nobody on this (busy) machine uses now: the rest may be anyone's.
    ids = free_ids(3)
    env[POOL_ENV] = ",".join(map(str, ids))
    plain = run_cli(["status"], env)
    assert plain.returncode == 0, plain.stderr
    listed = run_cli(["status", "--json"], env)
    assert listed.returncode == 0, listed.stderr
    assert json.loads(listed.stdout) == []
    assert plain.stdout.strip() == f"No domain ID of the pool is held (lock directory {lock_dir})."
    # Control: the same status sees one of them taken (its port bound, as upstream does).
    port = claim_port(ids[0])
    assert port is not None
    try:
        listed = run_cli(["status", "--json"], env)
    finally:
        port.close()
    assert listed.returncode == 0, listed.stderr
    assert json.loads(listed.stdout) == [{"domain_id": ids[0], "via": "port"}]
