"""The final sweep ends the test's whole tree, and what it cannot end keeps the ID blocked.

Real processes and real signals: a daemon that ignores SIGTERM and forks continually
(each child through ``env -i``, so no squatter scan sees it), a well-behaved daemon that
must still get its SIGTERM, and a setuid-root process the runner (user nobody) may not
signal at all. Every process a test starts carries a tag of its own in its command line:
"nothing survived" is checked across the whole machine, and teardown kills whatever
carries the tag, whatever went wrong.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from helpers.commands import HUNG, ament, run_cli
from helpers.domains import free_ids
from helpers.processes import stat_of
from helpers.results import load_result
from helpers.survivors import alive_with, build_setuid_helper, kill_all_with, new_tag

from ros_isolated_test.domain_coordinator import holder
from ros_isolated_test.domain_coordinator.block import (
    block_marker,
    blocking_survivors,
    write_block,
)
from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
from ros_isolated_test.domain_coordinator.status import held_domains
from ros_isolated_test.process import proc, supervisor
from ros_isolated_test.process.capture import OutputCapture

NOBODY = 65534
DEADLINE = 60.0
POOL_VAR = "ROS_ISOLATED_TEST_DOMAINS"

#: The red team's daemon. argv: env path, tag, seconds between children. The test's
#: main process returns once the daemon runs; the daemon ignores SIGTERM (so do its
#: children: an ignored signal stays ignored across fork and exec) and starts one
#: ``env -i sleep <tag>`` after another for ever. The tag is a number sleep accepts.
FORKING_DAEMON = """
import os, signal, sys, time
env, tag, period = sys.argv[1], sys.argv[2], float(sys.argv[3])
signal.signal(signal.SIGTERM, signal.SIG_IGN)
if os.fork():
    time.sleep(0.3)
    os._exit(0)
while True:
    os.posix_spawn(env, [env, "-i", "sleep", tag], {})
    time.sleep(period)
"""

#: A daemon that logs what happens to it. argv: events file, exits on SIGTERM (1/0), tag.
#: On SIGTERM it logs "term", and if it exits on it, takes a moment to shut down cleanly
#: (a SIGKILL sent too early would cut that short) and logs "exit".
LOGGING_DAEMON = """
import os, signal, sys, time
events, exits = sys.argv[1], sys.argv[2] == "1"
def log(what):
    with open(events, "a") as handle:
        handle.write(what + "\\n")
def on_term(signum, frame):
    log("term")
    if exits:
        time.sleep(0.3)
        log("exit")
        os._exit(0)
signal.signal(signal.SIGTERM, on_term)
read, write = os.pipe()
if os.fork():
    os.read(read, 1)
    os._exit(0)
log(f"started {os.getpid()}")
os.write(write, b"x")
while True:
    time.sleep(0.05)
"""


@pytest.fixture
def tags() -> Iterator[Callable[[], str]]:
    """Unique tags (numbers ``sleep`` accepts); all their processes are killed at the end."""
    made: list[str] = []

    def new() -> str:
        made.append(new_tag())
        return made[-1]

    yield new
    for tag in made:
        kill_all_with(tag)


# -- the red team's case: a daemon that ignores SIGTERM and forks through env -i ---------------


def _forking_daemon(tmp_path: Path, tag: str, period: float) -> list[str]:
    script = tmp_path / "forking_daemon.py"
    script.write_text(FORKING_DAEMON)
    env_tool = shutil.which("env")
    assert env_tool is not None
    return [sys.executable, str(script), env_tool, tag, str(period)]


@pytest.mark.parametrize("attempt", range(4))
def test_a_forking_daemon_that_ignores_sigterm_leaves_nothing_behind(
    attempt: int, one_id: dict[str, str], tmp_path: Path, tags: Callable[[], str]
) -> None:
    """Through ``run``: once the runner exits, no process of the test lives, every time."""
    del attempt  # repeated: the old sweep lost the race in most runs, not all
    tag = tags()
    result = tmp_path / "result.xml"
    command = _forking_daemon(tmp_path, tag, 0.002)
    done = run_cli(
        ["run", "--kill-grace", "0.5", "--junit-xml", str(result), "--", *command],
        one_id,
        cwd=tmp_path,
    )
    survivors = alive_with(tag)
    assert done.returncode == 0, done.stdout + done.stderr
    assert survivors == [], f"still alive after the runner exited: {survivors}\n{done.stdout}"
    assert "stopped process" in done.stdout
    assert "could not be ended" not in done.stdout
    properties = load_result(result).properties
    assert "(sleep)" in properties["leftover_processes"]
    assert "surviving_processes" not in properties


def test_a_forking_daemon_leaves_nothing_behind_the_ctest_runner(
    one_id: dict[str, str], tmp_path: Path, tags: Callable[[], str], runner_script: str
) -> None:
    """The same through the RUNNER script, with ctest's default grace of 5 s."""
    tag = tags()
    result = tmp_path / "pkg" / "result.xml"
    command = _forking_daemon(tmp_path, tag, 0.01)
    done = ament(
        runner_script, result, command, one_id, "--generate-result-on-success", cwd=tmp_path
    )
    survivors = alive_with(tag)
    assert done.returncode == 0, done.stdout + done.stderr
    assert survivors == [], f"still alive after the runner exited: {survivors}\n{done.stdout}"
    assert "stopped process" in done.stdout


# -- a well-behaved daemon still gets its SIGTERM, and its chance ------------------------------


@pytest.mark.parametrize("exits_on_term", [True, False], ids=["exits-on-term", "ignores-term"])
def test_a_daemon_gets_sigterm_and_its_grace_before_any_sigkill(
    exits_on_term: bool, one_id: dict[str, str], tmp_path: Path, tags: Callable[[], str]
) -> None:
    """Exiting on SIGTERM, it shuts down cleanly; ignoring it (the control), it is killed.

    The order of events in its own log says which: a SIGKILL (or a SIGSTOP) sent before
    it finished shutting down would leave no "exit".
    """
    tag = tags()
    events = tmp_path / "events"
    script = tmp_path / "logging_daemon.py"
    script.write_text(LOGGING_DAEMON)
    grace = "60" if exits_on_term else "0.5"
    command = [sys.executable, str(script), str(events), "1" if exits_on_term else "0", tag]
    started = time.monotonic()
    done = run_cli(["run", "--kill-grace", grace, "--", *command], one_id, cwd=tmp_path)
    took = time.monotonic() - started
    assert done.returncode == 0, done.stdout + done.stderr
    assert alive_with(tag) == []
    log = events.read_text().split("\n")
    pid = int(log[0].split()[1])
    assert f"stopped process {pid} (python" in done.stdout
    if exits_on_term:
        assert log[1:] == ["term", "exit", ""]
        # It ended the grace period by exiting: the runner did not sit out the 60 s.
        assert took < 60
    else:
        assert log[1:] == ["term", ""]


# -- a program embedding the supervisor keeps its own children --------------------------------


def test_processes_started_before_the_test_are_not_the_tests(tags: Callable[[], str]) -> None:
    """Only the test's tree is swept: a child the embedding program had already is left alone."""
    tag = tags()
    own = subprocess.Popen(["sleep", tag])
    try:
        console = io.BytesIO()
        command = ["sh", "-c", f"sleep {tag} & exit 0"]
        outcome = supervisor.run(command, dict(os.environ), OutputCapture(console), None, 0.5)
        assert outcome.returncode == 0
        assert [name.endswith("(sleep)") for name in outcome.leftovers] == [True]
        assert str(own.pid) not in outcome.leftovers[0]
        assert own.poll() is None, "the embedding program's own child was signalled"
        assert alive_with(tag) == [own.pid]
    finally:
        own.kill()
        own.wait(HUNG)


# -- block records: what the coordinator does with them ---------------------------------------


@pytest.fixture
def sleeper(tags: Callable[[], str]) -> Iterator[subprocess.Popen[bytes]]:
    process = subprocess.Popen(["sleep", tags()])
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
    held = [item for item in held_domains(lock_dir, (domain_id,)) if item.via == "survivor"]
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
    assert holder.owned_file(record)


# -- a survivor for real: a setuid-root process a runner run as nobody may not signal ----------


@pytest.fixture
def survivor_setup(traversable_dir: Path, env: dict[str, str]) -> tuple[Path, Path, dict[str, str]]:
    """A setuid-root helper, a lock directory nobody can use, and the environment for it."""
    helper = build_setuid_helper(traversable_dir)
    locks = traversable_dir / "locks"
    locks.mkdir()
    os.chmod(locks, 0o1777)
    (domain_id,) = free_ids(1)
    runner_env = {
        **env,
        "ROS_ISOLATED_TEST_LOCK_DIR": str(locks),
        POOL_VAR: str(domain_id),
        "HOME": "/nonexistent",
        "USER": "nobody",
    }
    return helper, locks, runner_env


def test_a_process_the_runner_cannot_end_keeps_the_id_blocked(
    survivor_setup: tuple[Path, Path, dict[str, str]],
    traversable_dir: Path,
    tags: Callable[[], str],
) -> None:
    helper, locks, runner_env = survivor_setup
    domain_id = int(runner_env[POOL_VAR])
    tag = tags()
    result = traversable_dir / "result.xml"
    as_nobody = {"user": NOBODY, "group": NOBODY, "extra_groups": [], "cwd": traversable_dir}
    # Through env -i, as the red team's children: no squatter scan can see it either.
    command = ["env", "-i", str(helper), tag]
    done = run_cli(
        ["run", "--kill-grace", "0.5", "--junit-xml", str(result), "--", *command],
        runner_env,
        **as_nobody,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (survivor,) = alive_with(tag)
    # Root for real: the runner's user may not signal it. No ROS_DOMAIN_ID to see.
    assert os.stat(f"/proc/{survivor}").st_uid == 0
    assert b"ROS_DOMAIN_ID" not in Path(f"/proc/{survivor}/environ").read_bytes()
    name = f"{survivor} (setuid_helper)"
    # Named in the output and the result file ...
    assert f"process {name} of the test could not be ended" in done.stdout, done.stdout
    assert f"ROS_DOMAIN_ID {domain_id} stays blocked while {name} live" in done.stdout
    assert load_result(result).properties["surviving_processes"] == name
    assert name not in load_result(result).properties.get("leftover_processes", "")

    # ... and the ID stays blocked after the runner exited, for every user: here root.
    refused = run_cli(["run", "--wait-timeout", "0", "--", "true"], runner_env, cwd=traversable_dir)
    assert refused.returncode == 3, refused.stdout + refused.stderr
    assert f"{domain_id}: survivor pid {survivor}" in refused.stdout + refused.stderr
    listed = run_cli(["status", "--json"], runner_env)
    assert listed.returncode == 0, listed.stderr
    rows = [row for row in json.loads(listed.stdout) if row["via"] == "survivor"]
    assert [(row["domain_id"], row["pid"], row["user"]) for row in rows] == [
        (domain_id, survivor, "root")
    ]
    text = run_cli(["status"], runner_env)
    assert any(
        line.split()[:3] == [str(domain_id), "survivor", str(survivor)]
        for line in text.stdout.splitlines()
    ), text.stdout

    # The control: once the survivor is gone, the ID is handed out again.
    kill_all_with(tag)
    again = run_cli(["run", "--wait-timeout", "0", "--", "true"], runner_env, cwd=traversable_dir)
    assert again.returncode == 0, again.stdout + again.stderr
    assert f"Running with ROS_DOMAIN_ID {domain_id}" in again.stdout
    # Root wrote nothing of nobody's: the stale record and the marker stay, ignored.
    left = sorted(entry for entry in os.listdir(locks) if entry.endswith(".blocked"))
    assert [(locks / entry).stat().st_uid for entry in left] == [NOBODY, NOBODY], left
    assert left[0] == f"domain-{domain_id}.blocked"
