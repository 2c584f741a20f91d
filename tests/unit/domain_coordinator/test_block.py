"""Block records: survivors of an ID's last test keep the ID from every runner while they live.

A runner that could not end its test's whole tree writes the survivors down
(``write_block``) before it releases the ID; every reservation then asks
``blocking_survivors`` and takes the ID only once they are gone. A record names each
process by PID *and* start time (a recycled PID is another process), is judged only in
the boot and PID namespace that wrote it, and lives in the shared lock directory, so
nothing is ever written through a link planted there. Real processes: a ``sleep``
blocks while it lives, and each block has its control (the process gone, the ID free
again). The last test kills a runner outright: the orphans it leaves are found by the
scan and written down the same way.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers.commands import CLI, HUNG, run_cli
from helpers.domains import free_ids
from helpers.process_tree import Launcher, alive, kill_tagged, tagged, wait_for_pid
from helpers.processes import stat_of
from helpers.results import domain_of
from helpers.survivors import tagged as survivor_tag

from ros_isolated_test.domain_coordinator.block import (
    block_marker,
    blocking_survivors,
    write_block,
)
from ros_isolated_test.domain_coordinator.lock_dir import owned_file
from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
from ros_isolated_test.domain_coordinator.status import domain_uses
from ros_isolated_test.process import proc


@pytest.fixture
def sleeper() -> Iterator[subprocess.Popen[bytes]]:
    with survivor_tag() as tag:
        process = subprocess.Popen(["sleep", tag])
        yield process
        process.kill()
        process.wait(HUNG)


def test_a_block_record_keeps_the_id_while_its_process_lives(
    lock_dir: Path, sleeper: subprocess.Popen[bytes]
) -> None:
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, [domain_id])
    reservation = coordinator.try_reserve(["first"])
    assert reservation is not None
    record = reservation.block_for([stat_of(sleeper.pid)])
    reservation.release()
    assert record.stat().st_mode & 0o777 == 0o644
    assert coordinator.try_reserve(["second"]) is None
    held = [item for item in domain_uses(lock_dir, (domain_id,)) if item.via == "survivor"]
    assert [(item.domain_id, item.holder and item.holder.pid) for item in held] == [
        (domain_id, sleeper.pid)
    ]
    sleeper.kill()
    sleeper.wait(HUNG)
    # The control: with its process gone the record counts for nothing, and is cleaned.
    again = coordinator.try_reserve(["third"])
    assert again is not None and again.domain_id == domain_id
    again.release()
    assert not record.exists()
    assert not block_marker(lock_dir, domain_id).exists()


def test_a_recycled_pid_does_not_block(lock_dir: Path, sleeper: subprocess.Popen[bytes]) -> None:
    """Same PID, another start time: another process, the block is stale."""
    (domain_id,) = free_ids(1)
    real = stat_of(sleeper.pid)
    other = proc.Stat(real.pid, real.ppid, real.pgid, real.state, real.name, real.start + 1)
    write_block(lock_dir, domain_id, [other])
    assert blocking_survivors(lock_dir, domain_id) == []
    write_block(lock_dir, domain_id, [real])  # the control
    assert [item.key for item in blocking_survivors(lock_dir, domain_id)] == [real.key]


def test_records_of_another_boot_are_stale_and_of_another_namespace_not_ours_to_judge(
    lock_dir: Path, sleeper: subprocess.Popen[bytes]
) -> None:
    (domain_id,) = free_ids(1)
    record = write_block(lock_dir, domain_id, [stat_of(sleeper.pid)])
    text = record.read_text()
    assert blocking_survivors(lock_dir, domain_id) != []  # the control: as written, it blocks
    record.write_text(text.replace(f"boot {proc.boot_id()}", "boot another-boot"))
    assert blocking_survivors(lock_dir, domain_id, clean=True) == []
    assert not record.exists(), "a record of another boot is removed"
    record = write_block(lock_dir, domain_id, [stat_of(sleeper.pid)])
    record.write_text(record.read_text().replace(proc.pid_namespace(), "pid:[1]"))
    assert blocking_survivors(lock_dir, domain_id, clean=True) == []
    assert record.exists(), "a record of another PID namespace is kept for its own runners"
    assert block_marker(lock_dir, domain_id).exists()


def test_planted_block_files_are_never_followed(
    lock_dir: Path, sleeper: subprocess.Popen[bytes], tmp_path: Path
) -> None:
    """A symlink at the marker or a record path: nothing is written through it."""
    (domain_id,) = free_ids(1)
    target = tmp_path / "target"
    target.write_text("untouched")
    block_marker(lock_dir, domain_id).symlink_to(target)
    planted = lock_dir / f"domain-{domain_id}.uid{os.getuid()}.planted.blocked"
    planted.symlink_to(target)
    assert blocking_survivors(lock_dir, domain_id, clean=True) == []
    record = write_block(lock_dir, domain_id, [stat_of(sleeper.pid)])
    assert target.read_text() == "untouched"
    assert [item.pid for item in blocking_survivors(lock_dir, domain_id)] == [sleeper.pid]
    assert owned_file(record)


def test_a_record_names_its_processes_under_this_boot_and_namespace(
    lock_dir: Path, sleeper: subprocess.Popen[bytes]
) -> None:
    """The marker first, then a record of this user's own, never one guessed beforehand."""
    (domain_id,) = free_ids(1)
    assert blocking_survivors(lock_dir, domain_id) == [], "no marker: nothing to read"
    stat = stat_of(sleeper.pid)
    first = write_block(lock_dir, domain_id, [stat])
    second = write_block(lock_dir, domain_id, [stat])
    assert block_marker(lock_dir, domain_id).is_file()
    assert first != second, "a second block writes a record of its own"
    for record in (first, second):
        assert record.name.startswith(f"domain-{domain_id}.uid{os.getuid()}.")
        assert record.read_text().splitlines() == [
            "ros-isolated-test survivors 1",
            f"boot {proc.boot_id()}",
            f"pidns {proc.pid_namespace()}",
            f"{stat.pid} {stat.start}",
        ]
    assert [item.pid for item in blocking_survivors(lock_dir, domain_id)] == [stat.pid] * 2


def test_a_file_that_is_no_record_blocks_nothing_and_is_left_alone(
    lock_dir: Path, sleeper: subprocess.Popen[bytes]
) -> None:
    """Not ours to judge: kept (with the marker) by ``clean``; a real record beside it blocks."""
    (domain_id,) = free_ids(1)
    odd = lock_dir / f"domain-{domain_id}.uid{os.getuid()}.odd.blocked"
    stat = stat_of(sleeper.pid)
    # A record in all but its first line, which names another format.
    body = [f"boot {proc.boot_id()}", f"pidns {proc.pid_namespace()}", f"{stat.pid} {stat.start}"]
    odd.write_text("\n".join(["some other program 1", *body]) + "\n")
    block_marker(lock_dir, domain_id).touch()
    assert blocking_survivors(lock_dir, domain_id, clean=True) == []
    assert odd.exists() and block_marker(lock_dir, domain_id).exists()
    write_block(lock_dir, domain_id, [stat])  # the control
    assert [item.pid for item in blocking_survivors(lock_dir, domain_id)] == [sleeper.pid]


# --- a runner killed with SIGKILL: its orphans are written down as survivors ----------------


def test_orphans_of_a_killed_runner_keep_their_id_from_other_tests(
    tree_env: dict[str, str], domain: int, launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    script = "sleep 60 & echo $! > child.pid; echo $$ > main.pid; exec sleep 60"
    log = tmp_path / "runner.log"
    runner = launcher.start([CLI, "run", "--", "sh", "-c", script], tree_env, log, cwd=tmp_path)
    child = wait_for_pid(tmp_path / "child.pid", process=runner, log=log)
    wait_for_pid(tmp_path / "main.pid", process=runner, log=log)
    os.kill(runner.pid, signal.SIGKILL)
    runner.wait()
    assert alive(child), "nothing outlived the runner: the scenario did not happen"

    status = run_cli(["status", "--json"], tree_env)
    assert status.returncode == 0, status.stdout + status.stderr
    rows = json.loads(status.stdout)
    squatters = [(row["domain_id"], row.get("pid")) for row in rows if row["via"] == "environment"]
    assert (domain, child) in squatters, status.stdout

    refused = run_cli(["run", "--wait-timeout", "0", "--", "true"], tree_env, cwd=tmp_path)
    assert refused.returncode == 3, refused.stdout + refused.stderr
    assert "no free ROS_DOMAIN_ID" in refused.stderr
    # The refused reservation's scan wrote the orphan down in a block record: from then on
    # it is named once, as a survivor (issue 30, item 9), no longer as a squatter too.
    assert f"survivor pid {child}" in refused.stderr, refused.stderr
    assert f"squatter pid {child}" not in refused.stderr, refused.stderr

    kill_tagged(tag)
    assert not tagged(tag)
    granted = run_cli(["run", "--", "true"], tree_env, cwd=tmp_path)
    assert granted.returncode == 0, granted.stdout + granted.stderr
    assert domain_of(granted.stdout) == domain
