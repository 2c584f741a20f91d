"""``reruns``: a failed test runs again on a fresh ID, and every attempt stays on record.

Real runners (``run`` and the ctest RUNNER), real shell and pytest tests whose state lives
in a file, so the first attempt fails and the next passes. Each flaky pass must show both
attempts on two different domain IDs (a pool of two IDs free now: the second attempt gets
the one released least recently, so never the first attempt's), a canonical file valid
against our schema and Jenkins' junit-10 rules with a ``flakyFailure`` and no failure,
and ``report`` must call it flaky; the same tests without reruns fail as before (the
control). What must never be rerun is checked against a failure that is: a refusal, an
exhausted pool. A signal, a kill, or a rerun that gets no ID: test_reruns_interrupted.py.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import ament, run_cli, run_runner
from helpers.domains import free_ids
from helpers.reruns import (
    COUNTING,
    FLAKY,
    flaky_pass_on_record,
    ids_of,
    properties_of,
    report_names_it_flaky,
    root_of,
    text_of,
    valid,
)
from lxml import etree

from ros_isolated_test.domain_coordinator import DomainCoordinator
from ros_isolated_test.runner.settings import MAX_RERUNS


def test_run_reruns_a_flaky_test_on_another_id_and_keeps_the_failure(
    two_ids: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "out" / "flaky.xml"
    command = ["sh", "-c", FLAKY, "flaky", str(tmp_path / "state")]
    proc = run_cli(
        ["run", "--rerun-failures", "2", "--junit-xml", str(result), "--", *command], two_ids
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ids = ids_of(proc.stdout)
    assert len(ids) == 2 and ids[0] != ids[1], proc.stdout
    # The attempt line comes after attempt 1's output and before attempt 2 starts.
    first = proc.stdout.index(f"failed on {ids[0]}")
    line = proc.stdout.index("ros-isolated-test: attempt 2 of 3: attempt 1 failed (exit code 1)")
    assert first < line < proc.stdout.index(f"passed on {ids[1]}"), proc.stdout
    assert "attempt 3" not in proc.stdout, proc.stdout
    flaky_pass_on_record(result, ids)
    report_names_it_flaky(result, two_ids)


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
        assert len(ids_of(proc.stdout)) == 1 and "attempt 2" not in proc.stdout, proc.stdout
        root = valid(result)
        assert root.find(".//failure") is not None and root.find(".//flakyFailure") is None
        assert "attempts" not in properties_of(result)


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
        ids = ids_of(proc.stdout)
        assert len(ids) == 2 and ids[0] != ids[1], proc.stdout
        assert "attempt 2 of 2: attempt 1 failed (exit code 1)" in proc.stdout
        flaky_pass_on_record(result, ids)
        report_names_it_flaky(result, env)
    # The control: no reruns asked for, the RUNNER fails the flaky test as before.
    result = tmp_path / "pkg" / "once.xml"
    command = ["sh", "-c", FLAKY, "flaky", str(tmp_path / "state-once")]
    proc = ament(
        runner_script, result, command, two_ids, "--generate-result-on-success", cwd=tmp_path
    )
    assert proc.returncode == 1 and "attempt 2" not in proc.stdout, proc.stdout
    assert root_of(result).find(".//failure") is not None


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
    root = root_of(result)
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
    ids = ids_of(proc.stdout)
    assert len(ids) == 3 and ids[0] != ids[1] and ids[1] != ids[2], proc.stdout
    root = valid(result)
    (case,) = root.iter("testcase")
    assert case.find("failure") is not None and case.find("flakyFailure") is None
    reruns = case.findall("rerunFailure")
    assert len(reruns) == 2, etree.tostring(case)
    assert "attempt 1 on" in text_of(reruns[0])
    assert "attempt 3 on" in text_of(case.find("failure"))
    properties = properties_of(result)
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
    root = valid(result)
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
    assert "ROS_DOMAIN_ID" in str(root_of(result).xpath("string(.//failure/@message)"))
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
        assert root_of(results[name]).find(".//error") is not None, name
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
    assert properties_of(result)["attempts"] == "2"  # it did run again
    # Nor does a rerun copy the attempts so far (that was quadratic in the reruns).
    assert "copy" not in rerun


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
    assert len(ids_of(proc.stdout)) == 1 and "attempt 2" not in proc.stdout, proc.stdout
    valid(result)
    properties = properties_of(result)
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
