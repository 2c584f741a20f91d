"""``attempt``: one attempt at the test: hold an ID, run it, end its tree, record it, release.

The test runs on the ID it holds (marked as held for it, so a pytest inside sees the ID
is its own, not preset), which no other runner can take while it runs and every runner
can after; what the result records of the attempt is said and gathered in the order it
happens (the ID's line, then the invocation, then the test's output). What the test
left running is ended and named before the ID goes, and a leftover that keeps printing
cannot hold the runner. The command writes its own result beside the result path. In
process with real commands, and through a real ``run``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import CLI, run_process
from helpers.domains import free_ids
from helpers.holding import free_now, one_id_policy

from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
from ros_isolated_test.process import proc
from ros_isolated_test.process.capture import OutputCapture
from ros_isolated_test.runner import partition, settings
from ros_isolated_test.runner.attempt import attempt, command_of
from ros_isolated_test.runner.interruption import Guard
from ros_isolated_test.runner.request import Mode, RunRequest
from ros_isolated_test.xunit.result_file import ResultFile

#: The test: whether another runner could take its ID while it runs, the ID, the mark.
WHILE_IT_RUNS = """
import os, sys
from pathlib import Path
from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
domain_id = int(os.environ["ROS_DOMAIN_ID"])
taken = DomainCoordinator(Path(sys.argv[1]), [domain_id]).reserve_if_free(["probe"])
mark = os.environ["ROS_ISOLATED_TEST_HELD_DOMAIN_ID"]
print("held" if taken is None else "free", domain_id, mark)
"""


class Attempted:
    """One attempt run in process: what it returned, what it said, what it recorded."""

    def __init__(self, tmp_path: Path, lock_dir: Path, domain_id: int, command: list[str]) -> None:
        policy, config = one_id_policy(lock_dir, domain_id, base=os.environ)
        request = RunRequest(tuple(command), Mode.SHELL, config)
        self.result = ResultFile(tmp_path / "pkg" / "t.xml", command, "pkg", "t")
        self.result.prepare()
        assert self.result.write_placeholder()
        self.guard = Guard()
        console = tmp_path / "console"
        with console.open("wb", buffering=0) as stream:
            capture = OutputCapture(stream)
            assert not self.guard.test_started
            self.outcome, self.domain_id = attempt(
                request, 1, policy, config, self.result, capture, self.guard
            )
        self.lines = console.read_text().splitlines()


def test_the_test_runs_on_its_id_held_for_it_and_released_after(
    tmp_path: Path, lock_dir: Path
) -> None:
    (domain_id,) = free_ids(1)
    done = Attempted(
        tmp_path, lock_dir, domain_id, [sys.executable, "-c", WHILE_IT_RUNS, str(lock_dir)]
    )
    assert done.outcome.returncode == 0, done.lines
    assert done.domain_id == domain_id and done.guard.test_started
    # Held while it ran (no other runner could take it), and marked as held for it.
    ran = done.lines.index(f"held {domain_id} {domain_id}")
    gz_name = partition.for_this_runner(domain_id)
    header = done.lines.index(
        f"Running with ROS_DOMAIN_ID {domain_id} (Gazebo partition {gz_name})"
    )
    invoking = next(i for i, line in enumerate(done.lines) if "invoking in" in line)
    assert header < invoking < ran, done.lines
    properties = done.result.properties
    assert properties["ros_domain_id"] == str(domain_id)
    assert properties["domain_pool"] == str(domain_id)
    assert {"started_at", "ended_at"} <= properties.keys()
    assert "leftover_processes" not in properties  # the control of the test below
    assert free_now(DomainCoordinator(lock_dir, [domain_id]))  # released after


def test_what_the_test_left_running_is_ended_and_named_before_its_id_goes(
    tmp_path: Path, lock_dir: Path
) -> None:
    (domain_id,) = free_ids(1)
    pid_file = tmp_path / "pid"
    command = ["sh", "-c", 'sleep 600 & echo $! > "$0"; exit 0', str(pid_file)]
    done = Attempted(tmp_path, lock_dir, domain_id, command)
    assert done.outcome.returncode == 0, done.lines
    pid = int(pid_file.read_text())
    found = proc.read_stat(pid)
    assert found is None or not found.alive, "the leftover still runs"
    named = f"stopped process {pid} (sleep), left running by the test"
    assert f"-- ros-isolated-test: {named}" in done.lines, done.lines
    assert done.result.properties["leftover_processes"] == f"{pid} (sleep)"
    assert free_now(DomainCoordinator(lock_dir, [domain_id]))


@pytest.mark.parametrize("reruns", [0, 1])
def test_the_command_writes_its_own_result_beside_the_result_path(
    tmp_path: Path, reruns: int
) -> None:
    """So the result path holds the placeholder (or the record so far) until the runner
    adopts the attempt, with reruns or without."""
    path = tmp_path / "pkg" / "t.xml"
    command = ("pytest", f"--junit-xml={path}", "-x")
    config = settings.read({}, reruns=reruns)
    request = RunRequest(command, Mode.AMENT, config, result_file=path)
    result = ResultFile(path, command, "pkg", "t")
    own = path.with_name("t.xml.attempt2.orig")
    assert command_of(request, result, 2) == ("pytest", f"--junit-xml={own}", "-x")
    assert (result.own, result.in_place) == (own, False)
    # The control: a command that names no argument as the result path is the test's own,
    # as given, and said to write the result path itself.
    named = ("pytest", "-x")
    request = RunRequest(named, Mode.AMENT, config, result_file=path)
    assert command_of(request, result, 1) == named
    assert (result.own, result.in_place) == (None, True)


# --- a real run ---------------------------------------------------------------------------------


def test_a_leftover_that_keeps_printing_cannot_hold_the_runner(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Without a limit on draining, the runner waited for as long as the spammer lived."""
    spam = "(while :; do echo spam; sleep 0.05; done) & exit 0"
    try:  # the spammer never stops by itself: a runner that waits for it never ends
        proc = run_process([CLI, "run", "--", "sh", "-c", spam], env, cwd=tmp_path)
    except subprocess.TimeoutExpired:
        pytest.fail("the runner still waited for the spammer's output after 120 s")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "left running by the test" in proc.stdout
