"""``reruns`` interrupted: a signal, a kill, or a rerun that gets no ID never loses an attempt.

A signal to the runner ends the series at once, a rerun queued for its ID too, with
attempt 1's word kept; a rerun that gets no ID names where attempt 1's own file went.
ctest's TIMEOUT kills the runner's whole group with SIGKILL, which no handler sees: at
any point of a rerun (waiting for an ID, in attempt 1, between attempts, before or after
attempt 2 wrote its file) the result file left must fail and keep the earlier failure;
the same test stopped nowhere is the control, flaky and passing. The runner knows where
it is without a clock: the test command stops where it is told, and holders queue for
the pool's one ID while attempt 1 runs.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
from pathlib import Path

import pytest
from helpers.commands import ament, ament_args, run_cli, start_cli, start_runner
from helpers.processes import Children, poll_until, wait_for
from helpers.reruns import (
    COUNTING,
    properties_of,
    queued_holder,
    report_names_it_flaky,
    valid,
)
from lxml import etree

from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.domain_coordinator.queue import Queue


def test_a_signal_to_the_runner_ends_the_run_without_further_attempts(
    two_ids: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    state = tmp_path / "count"
    begun = tmp_path / "begun"
    script = f'{COUNTING.rsplit("; exit", 1)[0]}; : > "{begun}"; exec sleep 60'
    result = tmp_path / "signalled.xml"
    runner = start_cli(
        ["run", "--rerun-failures", "2", "--junit-xml", str(result),
         "--", "sh", "-c", script, "slow", str(state)],
        two_ids, tmp_path / "log", started,
    )  # fmt: skip
    wait_for(begun)
    runner.send_signal(signal.SIGTERM)
    assert runner.wait(timeout=120) == 128 + signal.SIGTERM
    log = (tmp_path / "log").read_text()
    assert state.read_text().strip() == "1", log
    assert "attempt 2" not in log, log
    properties = properties_of(result)
    assert properties.get("signal") == "SIGTERM" or "SIGTERM" in properties.get("exit", ""), (
        properties
    )


def hold_before_the_rerun(
    children: Children, lock_dir: Path, one_id: dict[str, str], begun: Path, release: Path
) -> subprocess.Popen[str]:
    """Attempt 1 begun, a holder queues, attempt 1 is released: the rerun must wait behind it."""
    wait_for(begun)
    holder = queued_holder(children, lock_dir, int(one_id["ROS_ISOLATED_TEST_DOMAINS"]))
    release.touch()
    assert children.first_line(holder) == "held"
    return holder


def test_a_signal_while_a_rerun_waits_for_its_id_ends_the_run_at_once(
    one_id: dict[str, str],
    lock_dir: Path,
    tmp_path: Path,
    children: Children,
    started: list[subprocess.Popen[bytes]],
) -> None:
    """A holder queued while attempt 1 runs gets the only ID first; the rerun waits behind it."""
    begun, release, state = tmp_path / "begun", tmp_path / "release", tmp_path / "count"
    script = (
        f'{COUNTING.rsplit("; exit", 1)[0]}; : > "{begun}"; '
        f'while [ ! -e "{release}" ]; do sleep 0.05; done; exit 1'
    )
    result = tmp_path / "waited.xml"
    log = tmp_path / "log"
    runner = start_cli(
        ["run", "--rerun-failures", "2", "--junit-xml", str(result),
         "--", "sh", "-c", script, "t", str(state)],
        one_id, log, started,
    )  # fmt: skip
    holder = hold_before_the_rerun(children, lock_dir, one_id, begun, release)
    poll_until(lambda: "waiting for a free ROS_DOMAIN_ID" in log.read_text(), "the rerun waits")
    runner.send_signal(signal.SIGTERM)
    assert runner.wait(timeout=120) == 1  # attempt 1's code: the rerun never ran
    said = log.read_text()
    assert "attempt 2 of 3: attempt 1 failed (exit code 1)" in said, said
    assert "attempt 2 did not run: interrupted by SIGTERM" in said, said
    assert state.read_text().strip() == "1", said
    root = valid(result)
    assert root.find(".//failure") is not None, etree.tostring(root)
    properties = properties_of(result)
    assert properties["signal_after_test"] == "SIGTERM", properties
    assert properties["attempts"] == "1", properties
    children.finish(holder)


#: Writes its own failing result file, then waits for the release file, then exits 1.
OWN_FILE_THEN_WAIT = (
    'printf \'%s\' \'<testsuite name="s" tests="1"><testcase classname="s" name="c">'
    '<failure message="own failure"/></testcase></testsuite>\' > "$1"; : > "$2"; '
    'while [ ! -e "$3" ]; do sleep 0.05; done; exit 1'
)


def test_a_rerun_that_gets_no_id_names_where_the_first_attempts_file_is(
    one_id: dict[str, str],
    lock_dir: Path,
    tmp_path: Path,
    children: Children,
    started: list[subprocess.Popen[bytes]],
) -> None:
    """The test's own file of attempt 1 moves to .attempt1.orig: the result names that file."""
    begun, release = tmp_path / "begun", tmp_path / "release"
    result = tmp_path / "no_id.xml"
    log = tmp_path / "log"
    runner = start_cli(
        # The rerun queues behind the holder (queued first), and gives up after 2 s.
        ["run", "--rerun-failures", "1", "--wait-timeout", "2", "--junit-xml", str(result),
         "--", "sh", "-c", OWN_FILE_THEN_WAIT, "t", str(result), str(begun), str(release)],
        one_id, log, started,
    )  # fmt: skip
    holder = hold_before_the_rerun(children, lock_dir, one_id, begun, release)
    assert runner.wait(timeout=120) == 1  # attempt 1's code: the rerun never ran
    said = log.read_text()
    assert "attempt 2 did not run" in said, said
    properties = properties_of(result)
    assert "rerun_not_run" in properties, properties
    kept = result.with_name(properties["original_result_file"])
    assert kept == result.with_name("no_id.xml.attempt1.orig"), properties
    assert b"own failure" in kept.read_bytes()
    assert not result.with_name("no_id.xml.orig").exists()
    children.finish(holder)


def test_a_runner_killed_during_a_rerun_leaves_the_earlier_failure_on_record(
    two_ids: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """ctest's TIMEOUT kills the runner with SIGKILL: the rerun's placeholder keeps attempt 1."""
    state = tmp_path / "state"
    pid_file = tmp_path / "pid"
    script = (
        'if [ -e "$1" ]; then echo $$ > "$2"; exec sleep 60; fi; '
        ': > "$1"; echo "failed on $ROS_DOMAIN_ID"; exit 1'
    )
    result = tmp_path / "killed.xml"
    runner = start_cli(
        ["run", "--rerun-failures", "1", "--junit-xml", str(result),
         "--", "sh", "-c", script, "slow", str(state), str(pid_file)],
        two_ids, tmp_path / "log", started,
    )  # fmt: skip
    poll_until(lambda: pid_file.is_file() and pid_file.read_text().strip() != "", "attempt 2")
    runner.kill()
    runner.wait(timeout=120)
    with contextlib.suppress(ProcessLookupError, ValueError):
        os.kill(int(pid_file.read_text()), signal.SIGKILL)  # the orphaned second attempt
    root = valid(result)
    text = etree.tostring(root, encoding="unicode")
    assert "failed on" in text, text  # attempt 1's failure, kept
    assert "the runner was killed before the test ended" in text, text  # attempt 2's placeholder
    assert properties_of(result)["attempts"] == "2"


#: A test writing its own result file (argv: that file, a state folder, where to stop):
#: attempt 1 fails, attempt 2 passes. Where the third argument says, it touches
#: ``stopped`` and stops for good, reading a FIFO no one writes to until the test does.
STOPS_WHERE_TOLD = """
own=$1 state=$2 point=$3
n=$(( $(cat "$state/count" 2>/dev/null || echo 0) + 1 )); echo "$n" > "$state/count"
stop() { if [ "$point" = "$1" ]; then : > "$state/stopped"; read _ < "$state/fifo"; fi; }
stop "attempt $n"
if [ "$n" = 1 ]; then
  printf '%s' '<testsuite name="s" tests="1"><testcase classname="s" name="c">' \
    '<failure message="attempt 1 failed"/></testcase></testsuite>' > "$own"
  exit 1
fi
stop "attempt $n before its file"
printf '%s' '<testsuite name="s" tests="1"><testcase classname="s" name="c"/></testsuite>' > "$own"
stop "attempt $n after its file"
exit 0
"""


KILL_POINTS = [
    "waiting for an ID",
    "attempt 1",
    "between attempts",
    "attempt 2 before its file",
    "attempt 2 after its file",
]


@pytest.mark.parametrize("point", KILL_POINTS)
def test_a_runner_killed_at_any_point_of_a_rerun_leaves_a_failing_result(
    runner_script: str,
    one_id: dict[str, str],
    lock_dir: Path,
    tmp_path: Path,
    children: Children,
    started: list[subprocess.Popen[bytes]],
    point: str,
) -> None:
    """SIGKILL to the RUNNER's whole process group, as ctest's TIMEOUT does, wherever it is.

    The test knows where the runner is without a clock: the test command stops where it
    is told, the first wait is for the pool's one ID held here, and between attempts the
    rerun waits behind a holder that queued while attempt 1 ran.
    """
    (domain_id,) = map(int, one_id["ROS_ISOLATED_TEST_DOMAINS"].split(","))
    state = tmp_path / "state"
    state.mkdir()
    os.mkfifo(state / "fifo")
    result = tmp_path / "pkg" / "t.xml"
    log = tmp_path / "log"
    stop_at = "attempt 1" if point == "between attempts" else point
    command = ["sh", "-c", STOPS_WHERE_TOLD, "t", str(result), str(state), stop_at]
    args = ament_args(result, command, "--env", "ROS_ISOLATED_TEST_RERUNS=1")
    with contextlib.ExitStack() as stack:
        if point == "waiting for an ID":
            stack.enter_context(DomainCoordinator(lock_dir, [domain_id]).reserve(["holder"]))
        runner = start_runner(runner_script, args, one_id, log, started, start_new_session=True)
        if point == "waiting for an ID":
            poll_until(lambda: bool(Queue(lock_dir).waiters()), "the runner queued")
        else:
            wait_for(state / "stopped")
        if point == "between attempts":
            holder = queued_holder(children, lock_dir, domain_id)
            with open(state / "fifo", "wb"):
                pass  # attempt 1 goes on: it fails, and the rerun waits behind the holder
            assert children.first_line(holder) == "held"
            poll_until(lambda: "waiting for a free ROS_DOMAIN_ID" in log.read_text(), "the rerun")
        os.killpg(runner.pid, signal.SIGKILL)
        assert runner.wait(timeout=120) == -signal.SIGKILL, log.read_text()
    shown = run_cli(["report", "--json", str(result)], one_id)
    assert shown.returncode == 1, shown.stdout + shown.stderr + result.read_text()
    total = json.loads(shown.stdout)["total"]
    assert total["failures"] + total["errors"] >= 1, total
    root = valid(result)
    text = etree.tostring(root, encoding="unicode")
    assert "the runner was killed before the test ended" in text, text
    if point not in ("waiting for an ID", "attempt 1"):
        assert "attempt 1 failed" in text, text  # the earlier failure, on record
        assert properties_of(result)["attempts"] == "2", text
    if point == "attempt 2 after its file":
        # The passing file attempt 2 wrote is kept beside the result, never in its place.
        assert b'name="c"/>' in result.with_name("t.xml.attempt2.orig").read_bytes()


def test_control_a_rerun_of_a_test_writing_its_own_file_that_finishes_merges_its_attempts(
    runner_script: str, one_id: dict[str, str], tmp_path: Path
) -> None:
    """The same test, stopped nowhere: failing then passing is flaky, and report passes it."""
    state = tmp_path / "state"
    state.mkdir()
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", STOPS_WHERE_TOLD, "t", str(result), str(state), "nowhere"]
    options = ("--env", "ROS_ISOLATED_TEST_RERUNS=1")
    proc = ament(runner_script, result, command, one_id, *options, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    root = valid(result)
    (case,) = root.iter("testcase")
    (flaky,) = case.findall("flakyFailure")
    assert flaky.get("message") == "attempt 1 failed", etree.tostring(root)
    assert case.find("failure") is None and case.find("error") is None
    assert properties_of(result)["attempts"] == "2"
    # Each attempt's own file is kept, as without the redirection: the last one's as .orig.
    assert b"attempt 1 failed" in result.with_name("t.xml.attempt1.orig").read_bytes()
    assert b'name="c"/>' in result.with_name("t.xml.orig").read_bytes()
    report_names_it_flaky(result, one_id)
