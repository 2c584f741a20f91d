"""Reruns: a failed test runs again on a fresh ID, and every attempt stays on record.

Real runners (``run`` and the ctest RUNNER), real shell and pytest tests whose state lives
in a file, so the first attempt fails and the next passes. Each flaky pass must show both
attempts on two different domain IDs (a pool of two IDs free now: the second attempt gets
the one released least recently, so never the first attempt's), a canonical file valid
against our schema and Jenkins' junit-10 rules with a ``flakyFailure`` and no failure,
and ``report`` must call it flaky; the same tests without reruns fail as before (the
control). What must never be rerun is checked against a failure that is: a refusal, an
exhausted pool, a signal to the runner.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities, jenkins_junit10
from helpers.commands import ament, ament_args, run_cli, run_runner, start_cli, start_runner
from helpers.domains import free_ids
from helpers.processes import Children, poll_until, wait_for
from lxml import etree

from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.domain_coordinator.queue import Queue
from ros_isolated_test.runner.settings import MAX_RERUNS
from ros_isolated_test.schemas import junit_schema
from ros_isolated_test.xunit.attempts import merge_attempts
from ros_isolated_test.xunit.model import Outcome
from ros_isolated_test.xunit.result_file import ResultFile

#: Fails the first time (no state file yet), passes after: the flake, made certain.
FLAKY = (
    'if [ -e "$1" ]; then echo "passed on $ROS_DOMAIN_ID"; exit 0; fi; '
    ': > "$1"; echo "failed on $ROS_DOMAIN_ID"; exit 1'
)
#: Fails every time, with 10 + the attempt's number: the exit code says which attempt it was.
COUNTING = (
    'n=$(( $(cat "$1" 2>/dev/null || echo 0) + 1 )); echo "$n" > "$1"; '
    'echo "attempt $n on $ROS_DOMAIN_ID"; exit $((10 + n))'
)
DOMAIN_LINE = re.compile(r"^Running with ROS_DOMAIN_ID (\d+)\b", re.MULTILINE)


@pytest.fixture
def two_ids(env: dict[str, str]) -> dict[str, str]:
    """The runner environment with a pool of two IDs free now."""
    return {**env, "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(2)))}


def _ids(stdout: str) -> list[int]:
    return [int(found) for found in DOMAIN_LINE.findall(stdout)]


def _root(path: Path) -> etree._Element:
    return etree.parse(str(path)).getroot()


def _properties(path: Path) -> dict[str, str]:
    return {item.get("name", ""): item.get("value", "") for item in _root(path).iter("property")}


def _valid(path: Path) -> etree._Element:
    """The canonical file's root, valid against our schema and junit-10's rules."""
    root = _root(path)
    schema = junit_schema()
    assert schema.validate(root), schema.error_log
    assert jenkins_junit10.rejections(root) == []
    return root


def _text(element: etree._Element | None) -> str:
    """An element's text, its children's (a stackTrace) included."""
    assert element is not None
    return "".join(str(part) for part in element.itertext())


def _flaky_pass_on_record(path: Path, ids: list[int]) -> None:
    """The flaky case has one flakyFailure (attempt 1) and no failure; both IDs noted."""
    root = _valid(path)
    (case,) = root.iter("testcase")
    assert case.find("failure") is None and case.find("error") is None
    (flaky,) = case.findall("flakyFailure")
    assert f"failed on {ids[0]}" in _text(flaky), etree.tostring(flaky)
    properties = _properties(path)
    assert properties["attempts"] == "2", properties
    assert properties["ros_domain_ids"] == f"{ids[0]}, {ids[1]}", properties
    assert properties["ros_domain_id"] == str(ids[1]), properties
    assert root.find("testsuite").get("failures") == "0"  # type: ignore[union-attr]


def _report_names_it_flaky(path: Path, env: dict[str, str]) -> None:
    shown = run_cli(["report", str(path)], env)
    assert shown.returncode == 0, shown.stdout + shown.stderr
    assert "Flaky: 1 case(s) passed after failing" in shown.stdout, shown.stdout
    as_json = run_cli(["report", "--json", str(path)], env)
    (row,) = json.loads(as_json.stdout)["files"]
    assert row["failures"] == 0 and len(row["flaky_cases"]) == 1, row


def test_run_reruns_a_flaky_test_on_another_id_and_keeps_the_failure(
    two_ids: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "out" / "flaky.xml"
    command = ["sh", "-c", FLAKY, "flaky", str(tmp_path / "state")]
    proc = run_cli(
        ["run", "--rerun-failures", "2", "--junit-xml", str(result), "--", *command], two_ids
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ids = _ids(proc.stdout)
    assert len(ids) == 2 and ids[0] != ids[1], proc.stdout
    # The attempt line comes after attempt 1's output and before attempt 2 starts.
    first = proc.stdout.index(f"failed on {ids[0]}")
    line = proc.stdout.index("ros-isolated-test: attempt 2 of 3: attempt 1 failed (exit code 1)")
    assert first < line < proc.stdout.index(f"passed on {ids[1]}"), proc.stdout
    assert "attempt 3" not in proc.stdout, proc.stdout
    _flaky_pass_on_record(result, ids)
    _report_names_it_flaky(result, two_ids)


def test_without_reruns_the_flaky_test_fails_as_before(
    two_ids: dict[str, str], tmp_path: Path
) -> None:
    """The control: the same test, no reruns asked for (or 0): one attempt, a failure."""
    for options in ([], ["--rerun-failures", "0"]):
        state = tmp_path / f"state{len(options)}"
        result = tmp_path / f"flaky{len(options)}.xml"
        command = ["sh", "-c", FLAKY, "flaky", str(state)]
        proc = run_cli(["run", *options, "--junit-xml", str(result), "--", *command], two_ids)
        assert proc.returncode == 1, proc.stdout + proc.stderr
        assert len(_ids(proc.stdout)) == 1 and "attempt 2" not in proc.stdout, proc.stdout
        root = _valid(result)
        assert root.find(".//failure") is not None and root.find(".//flakyFailure") is None
        assert "attempts" not in _properties(result)


def test_the_runner_reruns_a_flaky_test_from_its_variable_or_env(
    runner_script: str, two_ids: dict[str, str], tmp_path: Path
) -> None:
    """ROS_ISOLATED_TEST_RERUNS in the runner's environment, or as ament_add_test's ENV."""
    ways = {
        "variable": ({**two_ids, "ROS_ISOLATED_TEST_RERUNS": "1"}, ()),
        "env": (two_ids, ("--env", "ROS_ISOLATED_TEST_RERUNS=1")),
        # The test's ENV has the last word over the runner's environment.
        "env wins": (
            {**two_ids, "ROS_ISOLATED_TEST_RERUNS": "0"},
            ("--env", "ROS_ISOLATED_TEST_RERUNS=1"),
        ),
    }
    for number, (name, (env, options)) in enumerate(ways.items()):
        result = tmp_path / "pkg" / f"flaky{number}.xml"
        command = ["sh", "-c", FLAKY, "flaky", str(tmp_path / f"state{number}")]
        proc = ament(
            runner_script,
            result,
            command,
            env,
            "--generate-result-on-success",
            *options,
            cwd=tmp_path,
        )
        assert proc.returncode == 0, f"{name}: {proc.stdout}{proc.stderr}"
        ids = _ids(proc.stdout)
        assert len(ids) == 2 and ids[0] != ids[1], proc.stdout
        assert "attempt 2 of 2: attempt 1 failed (exit code 1)" in proc.stdout
        _flaky_pass_on_record(result, ids)
        _report_names_it_flaky(result, env)
    # The control: no reruns asked for, the RUNNER fails the flaky test as before.
    result = tmp_path / "pkg" / "once.xml"
    command = ["sh", "-c", FLAKY, "flaky", str(tmp_path / "state-once")]
    proc = ament(
        runner_script, result, command, two_ids, "--generate-result-on-success", cwd=tmp_path
    )
    assert proc.returncode == 1 and "attempt 2" not in proc.stdout, proc.stdout
    assert _root(result).find(".//failure") is not None


@capabilities.OUTSIDE
def test_a_flaky_pass_is_valid_against_the_real_junit10_schema(
    two_ids: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "flaky.xml"
    command = ["sh", "-c", FLAKY, "flaky", str(tmp_path / "state")]
    proc = run_cli(
        ["run", "--rerun-failures", "1", "--junit-xml", str(result), "--", *command], two_ids
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    schema = etree.XMLSchema(etree.parse(str(capabilities.JENKINS_JUNIT10_XSD), parser))
    root = _root(result)
    assert root.find(".//flakyFailure") is not None
    assert schema.validate(root), schema.error_log


def test_a_test_that_always_fails_runs_n_plus_one_times_and_exits_with_the_last_code(
    two_ids: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "always.xml"
    state = tmp_path / "count"
    command = ["sh", "-c", COUNTING, "always", str(state)]
    proc = run_cli(
        ["run", "--rerun-failures", "2", "--junit-xml", str(result), "--", *command], two_ids
    )
    assert proc.returncode == 13, proc.stdout + proc.stderr
    assert state.read_text().strip() == "3"
    assert "attempt 2 of 3: attempt 1 failed (exit code 11)" in proc.stdout
    assert "attempt 3 of 3: attempt 2 failed (exit code 12)" in proc.stdout
    ids = _ids(proc.stdout)
    assert len(ids) == 3 and ids[0] != ids[1] and ids[1] != ids[2], proc.stdout
    root = _valid(result)
    (case,) = root.iter("testcase")
    assert case.find("failure") is not None and case.find("flakyFailure") is None
    reruns = case.findall("rerunFailure")
    assert len(reruns) == 2, etree.tostring(case)
    assert "attempt 1 on" in _text(reruns[0])
    assert "attempt 3 on" in _text(case.find("failure"))
    properties = _properties(result)
    assert properties["attempts"] == "3" and properties["exit_code"] == "13", properties
    shown = run_cli(["report", "--json", str(result)], two_ids)
    assert shown.returncode == 1, shown.stdout
    assert json.loads(shown.stdout)["total"]["failures"] == 1


def test_a_timeout_is_rerun(two_ids: dict[str, str], tmp_path: Path) -> None:
    state = tmp_path / "state"
    script = 'if [ -e "$1" ]; then exit 0; fi; : > "$1"; exec sleep 60'
    proc = run_cli(
        ["run", "--rerun-failures", "1", "--timeout", "5", "--kill-grace", "1",
         "--", "sh", "-c", script, "slow", str(state)],
        two_ids,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "attempt 2 of 2: attempt 1 failed (timed out)" in proc.stdout, proc.stdout


def test_a_test_writing_its_own_result_file_is_flaky_per_case(
    runner_script: str, two_ids: dict[str, str], tmp_path: Path
) -> None:
    """pytest --junitxml into RESULT_FILE: each attempt's file is read before the next runs."""
    test_file = tmp_path / "test_flaky.py"
    test_file.write_text(
        "import os, pathlib\n"
        "STATE = pathlib.Path(os.environ['FLAKY_STATE'])\n"
        "def test_stable():\n    pass\n"
        "def test_flaky():\n"
        "    first = not STATE.exists()\n"
        "    STATE.write_text('ran')\n"
        "    assert not first, 'the first attempt fails'\n"
    )
    result = tmp_path / "pkg" / "test_flaky.xml"
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
               f"--junitxml={result}", str(test_file)]  # fmt: skip
    options = ("--env", f"FLAKY_STATE={tmp_path / 'state'}", "ROS_ISOLATED_TEST_RERUNS=2")
    proc = ament(runner_script, result, command, two_ids, *options, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "attempt 2 of 3: attempt 1 failed (exit code 1)" in proc.stdout, proc.stdout
    root = _valid(result)
    cases = {case.get("name"): case for case in root.iter("testcase")}
    assert set(cases) == {"test_stable", "test_flaky"}, list(cases)
    assert len(cases["test_stable"]) == 0, etree.tostring(cases["test_stable"])
    (flaky,) = cases["test_flaky"].findall("flakyFailure")
    assert "the first attempt fails" in (flaky.get("message") or ""), etree.tostring(flaky)
    assert cases["test_flaky"].find("failure") is None
    # Each attempt's own file is kept: the first one's beside the last one's.
    first = result.with_name("test_flaky.xml.attempt1.orig")
    assert b"the first attempt fails" in first.read_bytes()
    assert b"the first attempt fails" not in result.with_name("test_flaky.xml.orig").read_bytes()


def test_a_refusal_is_never_rerun(two_ids: dict[str, str], tmp_path: Path) -> None:
    state = tmp_path / "count"
    result = tmp_path / "refused.xml"
    args = ["run", "--rerun-failures", "2", "--junit-xml", str(result), "--",
            "sh", "-c", COUNTING, "always", str(state)]  # fmt: skip
    proc = run_cli(args, {**two_ids, "ROS_DOMAIN_ID": "7"})
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not state.exists() and "attempt 2" not in proc.stdout + proc.stderr
    assert "ROS_DOMAIN_ID" in str(_root(result).xpath("string(.//failure/@message)"))
    # The control: without the preset ID the same failing command does run again.
    control = run_cli(args, two_ids)
    assert control.returncode == 13, control.stdout + control.stderr


def test_an_exhausted_pool_is_never_rerun(
    env: dict[str, str], lock_dir: Path, tmp_path: Path
) -> None:
    (domain_id,) = free_ids(1)
    one = {**env, "ROS_ISOLATED_TEST_DOMAINS": str(domain_id)}
    state = tmp_path / "count"
    args = ["run", "--rerun-failures", "2", "--wait-timeout", "0",
            "--", "sh", "-c", COUNTING, "always", str(state)]  # fmt: skip
    with DomainCoordinator(lock_dir, [domain_id]).reserve(["holder"]):
        proc = run_cli(args, one)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert not state.exists() and "attempt 2" not in proc.stdout + proc.stderr
    control = run_cli(args, one)  # the ID released: all three attempts run
    assert control.returncode == 13, control.stdout + control.stderr


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
    properties = _properties(result)
    assert properties.get("signal") == "SIGTERM" or "SIGTERM" in properties.get("exit", ""), (
        properties
    )


@pytest.mark.parametrize("value", ["-1", "x", "1.5", str(MAX_RERUNS + 1)])
def test_a_bad_rerun_count_is_a_usage_error_with_a_result_file(
    runner_script: str, env: dict[str, str], tmp_path: Path, value: str
) -> None:
    state = tmp_path / "ran"
    command = ["sh", "-c", ': > "$1"', "t", str(state)]
    bad = {**env, "ROS_ISOLATED_TEST_RERUNS": value}
    results = {
        name: tmp_path / "pkg" / f"{name}.xml" for name in ("option", "variable", "runner", "env")
    }
    tries = {
        "option": run_cli(
            ["run", f"--rerun-failures={value}", "--junit-xml", str(results["option"]),
             "--", *command], env,
        ),
        "variable": run_cli(["run", "--junit-xml", str(results["variable"]), "--", *command], bad),
        "runner": run_runner(runner_script, [str(results["runner"]), "--command", *command], bad),
        "env": run_runner(
            runner_script,
            [str(results["env"]), "--env", f"ROS_ISOLATED_TEST_RERUNS={value}",
             "--command", *command],
            env,
        ),
    }  # fmt: skip
    for name, proc in tries.items():
        assert proc.returncode == 2, f"{name}: {proc.stdout}{proc.stderr}"
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("ros-isolated-test: error:"), (name, lines)
        assert value in lines[0] and "rerun" in lines[0].lower(), (name, lines)
        assert _root(results[name]).find(".//error") is not None, name
    assert not state.exists()


def test_the_option_wins_over_the_variable_and_run_honours_the_variable(
    two_ids: dict[str, str], tmp_path: Path
) -> None:
    def attempts(options: list[str], variable: str | None, name: str) -> int:
        env = dict(two_ids)
        if variable is not None:
            env["ROS_ISOLATED_TEST_RERUNS"] = variable
        state = tmp_path / name
        proc = run_cli(["run", *options, "--", "sh", "-c", COUNTING, "t", str(state)], env)
        assert proc.returncode == 10 + int(state.read_text()), proc.stdout + proc.stderr
        return int(state.read_text())

    assert attempts([], "1", "variable") == 2
    assert attempts(["--rerun-failures", "0"], "2", "option zero") == 1
    assert attempts(["--rerun-failures", "2"], "0", "option two") == 3


def _imported(argv: list[str], env: dict[str, str], cwd: Path) -> set[str]:
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", *argv],
        env=env, cwd=cwd, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    return {
        line.rsplit("|", 1)[1].strip()
        for line in proc.stderr.splitlines()
        if line.startswith("import time:") and "|" in line
    }


def test_without_reruns_the_runner_imports_nothing_of_them(
    runner_script: str, two_ids: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", FLAKY, "flaky", str(tmp_path / "state")]
    args = ["-u", runner_script, str(result), "--generate-result-on-success"]
    plain = _imported([*args, "--command", *command], two_ids, tmp_path)
    assert "ros_isolated_test.runner.session" in plain, "the check must see the real run"
    assert "copy" not in plain
    (tmp_path / "state").unlink()
    rerun = _imported(
        [*args, "--env", "ROS_ISOLATED_TEST_RERUNS=1", "--command", *command], two_ids, tmp_path
    )
    assert "ros_isolated_test.runner.session" in rerun, "the check must see the real rerun"
    assert _properties(result)["attempts"] == "2"  # it did run again
    # Nor does a rerun copy the attempts so far (that was quadratic in the reruns).
    assert "copy" not in rerun


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
    root = _valid(result)
    text = etree.tostring(root, encoding="unicode")
    assert "failed on" in text, text  # attempt 1's failure, kept
    assert "the runner was killed before the test ended" in text, text  # attempt 2's placeholder
    assert _properties(result)["attempts"] == "2"


def test_a_test_that_passes_at_once_runs_once_and_says_so(
    two_ids: dict[str, str], tmp_path: Path
) -> None:
    """Also the control of the cap on N: the documented maximum itself is accepted."""
    result = tmp_path / "once.xml"
    most = str(MAX_RERUNS)
    proc = run_cli(
        ["run", "--rerun-failures", most, "--junit-xml", str(result), "--", "true"], two_ids
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(_ids(proc.stdout)) == 1 and "attempt 2" not in proc.stdout, proc.stdout
    _valid(result)
    properties = _properties(result)
    assert (properties["attempts"], properties["rerun_failures"]) == ("1", most), properties


def test_the_rerun_count_does_not_reach_the_test(
    runner_script: str, two_ids: dict[str, str], tmp_path: Path
) -> None:
    """A runner started inside the test would rerun on top of this one's reruns."""
    code = "import os; print('seen:', os.environ.get('ROS_ISOLATED_TEST_RERUNS'))"
    show = [sys.executable, "-c", code]
    proc = run_cli(["run", "--", *show], {**two_ids, "ROS_ISOLATED_TEST_RERUNS": "2"})
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen: None" in proc.stdout, proc.stdout
    result = tmp_path / "shown.xml"
    options = ("--env", "ROS_ISOLATED_TEST_RERUNS=1")
    runner = ament(runner_script, result, show, two_ids, *options, cwd=tmp_path)
    assert "seen: None" in runner.stdout, runner.stdout + runner.stderr
    # The control: any other variable reaches the test as it is.
    shown = [sys.executable, "-c", "import os; print('seen:', os.environ.get('OTHER_VARIABLE'))"]
    other = run_cli(["run", "--", *shown], {**two_ids, "OTHER_VARIABLE": "2"})
    assert "seen: 2" in other.stdout, other.stdout


#: Queues for the one ID (first come, first served), prints "held" once it has it, holds it
#: until stdin closes. argv: lock dir, ID.
QUEUE_AND_HOLD = """
import sys
from pathlib import Path
from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.domain_coordinator.queue import Queue
coordinator = DomainCoordinator(Path(sys.argv[1]), [int(sys.argv[2])])
reservation = coordinator.acquire(["queued holder"], wait_timeout=120)
print("held", flush=True)
sys.stdin.read()
reservation.release()
"""


def test_a_signal_while_a_rerun_waits_for_its_id_ends_the_run_at_once(
    env: dict[str, str],
    lock_dir: Path,
    tmp_path: Path,
    children: Children,
    started: list[subprocess.Popen[bytes]],
) -> None:
    """A holder queued while attempt 1 runs gets the only ID first; the rerun waits behind it."""
    (domain_id,) = free_ids(1)
    one = {**env, "ROS_ISOLATED_TEST_DOMAINS": str(domain_id)}
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
        one, log, started,
    )  # fmt: skip
    wait_for(begun)
    holder = children.python(QUEUE_AND_HOLD, lock_dir, domain_id)
    poll_until(lambda: bool(Queue(lock_dir).waiters()), "the holder queued")
    release.touch()
    assert children.first_line(holder) == "held"
    poll_until(lambda: "waiting for a free ROS_DOMAIN_ID" in log.read_text(), "the rerun waits")
    runner.send_signal(signal.SIGTERM)
    assert runner.wait(timeout=120) == 1  # attempt 1's code: the rerun never ran
    said = log.read_text()
    assert "attempt 2 of 3: attempt 1 failed (exit code 1)" in said, said
    assert "attempt 2 did not run: interrupted by SIGTERM" in said, said
    assert state.read_text().strip() == "1", said
    root = _valid(result)
    assert root.find(".//failure") is not None, etree.tostring(root)
    properties = _properties(result)
    assert properties["signal_after_test"] == "SIGTERM", properties
    assert properties["attempts"] == "1", properties
    children.finish(holder)


def test_a_rerun_result_is_never_on_disk_without_the_earlier_attempts(tmp_path: Path) -> None:
    """The rerun's own result is written merged: a kill before the final merge loses nothing.

    The runner's result file driven as the rerun loop drives it, on a real file: after
    attempt 2 is written (the last write a kill before the final merge leaves), attempt
    1's failure is on disk beside it, while its own word (passed) still sets the exit code.
    """
    path = tmp_path / "pkg" / "t.xml"
    result = ResultFile(path, ("t",), "pkg", "t")
    result.prepare()
    assert result.write_placeholder()
    result.write([result.case(Outcome.FAILURE, "attempt one failed")])
    first = result.last_suite
    assert first is not None
    assert result.next_attempt(1, {}, lambda latest: merge_attempts([first, latest]))
    assert "attempt one failed" in path.read_text()  # the placeholder holds it (the control)
    rendered = result.write([result.case(Outcome.PASSED)])
    assert rendered is not None and not rendered.failed  # attempt 2's own word: it passed
    root = _valid(path)
    (case,) = root.iter("testcase")
    (flaky,) = case.findall("flakyFailure")
    assert flaky.get("message") == "attempt one failed", etree.tostring(root)
    assert _properties(path)["attempts"] == "2"
    assert result.last_suite is not None and len(result.last_suite.cases) == 1


#: Writes its own failing result file, then waits for the release file, then exits 1.
OWN_FILE_THEN_WAIT = (
    'printf \'%s\' \'<testsuite name="s" tests="1"><testcase classname="s" name="c">'
    '<failure message="own failure"/></testcase></testsuite>\' > "$1"; : > "$2"; '
    'while [ ! -e "$3" ]; do sleep 0.05; done; exit 1'
)


def test_a_rerun_that_gets_no_id_names_where_the_first_attempts_file_is(
    env: dict[str, str],
    lock_dir: Path,
    tmp_path: Path,
    children: Children,
    started: list[subprocess.Popen[bytes]],
) -> None:
    """The test's own file of attempt 1 moves to .attempt1.orig: the result names that file."""
    (domain_id,) = free_ids(1)
    one = {**env, "ROS_ISOLATED_TEST_DOMAINS": str(domain_id)}
    begun, release = tmp_path / "begun", tmp_path / "release"
    result = tmp_path / "no_id.xml"
    log = tmp_path / "log"
    runner = start_cli(
        # The rerun queues behind the holder (queued first), and gives up after 2 s.
        ["run", "--rerun-failures", "1", "--wait-timeout", "2", "--junit-xml", str(result),
         "--", "sh", "-c", OWN_FILE_THEN_WAIT, "t", str(result), str(begun), str(release)],
        one, log, started,
    )  # fmt: skip
    wait_for(begun)
    holder = children.python(QUEUE_AND_HOLD, lock_dir, domain_id)
    poll_until(lambda: bool(Queue(lock_dir).waiters()), "the holder queued")
    release.touch()
    assert children.first_line(holder) == "held"
    assert runner.wait(timeout=120) == 1  # attempt 1's code: the rerun never ran
    said = log.read_text()
    assert "attempt 2 did not run" in said, said
    properties = _properties(result)
    assert "rerun_not_run" in properties, properties
    kept = result.with_name(properties["original_result_file"])
    assert kept == result.with_name("no_id.xml.attempt1.orig"), properties
    assert b"own failure" in kept.read_bytes()
    assert not result.with_name("no_id.xml.orig").exists()
    children.finish(holder)


def test_an_attempts_file_that_cannot_be_kept_is_one_line_naming_the_fix(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Something in the way of ``.attempt1.orig`` (a folder the test made): say what to do."""
    path = tmp_path / "t.xml"

    def attempt_one(result: ResultFile) -> None:
        result.prepare()
        assert result.write_placeholder()
        path.write_text(
            '<testsuite name="s" tests="1"><testcase classname="s" name="c">'
            '<failure message="own failure"/></testcase></testsuite>'
        )
        result.write(result.adopt(), checked=True)

    # The control: nothing in the way, attempt 1's own file is kept, nothing said.
    kept = ResultFile(path, ("t",), "pkg", "t")
    attempt_one(kept)
    capsys.readouterr()
    assert kept.next_attempt(1, {}, lambda latest: latest)
    assert b"own failure" in path.with_name("t.xml.attempt1.orig").read_bytes()
    assert capsys.readouterr().err == ""
    blocked = ResultFile(path, ("t",), "pkg", "t")
    attempt_one(blocked)
    (path.with_name("t.xml.attempt1.orig") / "made by the test").mkdir(parents=True)
    capsys.readouterr()
    assert blocked.next_attempt(1, {}, lambda latest: latest)
    (line,) = capsys.readouterr().err.splitlines()
    assert "t.xml.attempt1.orig" in line and "remove what is in the way" in line, line


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
            holder = children.python(QUEUE_AND_HOLD, lock_dir, domain_id)
            poll_until(lambda: bool(Queue(lock_dir).waiters()), "the holder queued")
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
    root = _valid(result)
    text = etree.tostring(root, encoding="unicode")
    assert "the runner was killed before the test ended" in text, text
    if point not in ("waiting for an ID", "attempt 1"):
        assert "attempt 1 failed" in text, text  # the earlier failure, on record
        assert _properties(result)["attempts"] == "2", text
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
    root = _valid(result)
    (case,) = root.iter("testcase")
    (flaky,) = case.findall("flakyFailure")
    assert flaky.get("message") == "attempt 1 failed", etree.tostring(root)
    assert case.find("failure") is None and case.find("error") is None
    assert _properties(result)["attempts"] == "2"
    # Each attempt's own file is kept, as without the redirection: the last one's as .orig.
    assert b"attempt 1 failed" in result.with_name("t.xml.attempt1.orig").read_bytes()
    assert b'name="c"/>' in result.with_name("t.xml.orig").read_bytes()
    _report_names_it_flaky(result, one_id)
