"""``report.counts``: what a result file counts, from its cases, as ``report`` prints it.

A flaky case counts as passed and is listed apart; a case that failed in every attempt
is a failure, never flaky; a case that failed and was then not run is a failure, listed
apart too. The reruns are real runs through ``run --rerun-failures``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.report_text import (
    LINE,
    file_lines,
    summary_of,
)
from lxml import etree

from ros_isolated_test.report.counts import counted, summary_line, totals
from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE, merge_attempts
from ros_isolated_test.xunit.model import Attempt, Case, Outcome, Suite

# --- the counts, from the cases --------------------------------------------------------------


def test_counts_come_from_the_cases_and_a_flaky_pass_is_apart() -> None:
    flaky = Case("pkg.C", "flaky", attempts=[Attempt("flakyFailure", "first try")])
    cases = [
        Case("pkg.C", "passed"),
        Case.saying("pkg.C", "failed", Outcome.FAILURE, "m"),
        Case.saying("pkg.C", "errored", Outcome.ERROR, "m"),
        Case.saying("pkg.C", "not run", Outcome.FAILURE, "m", NOT_RUN_AGAIN_TYPE),
        Case.saying("pkg.C", "skipped", Outcome.SKIPPED, "m"),
        flaky,
    ]
    report = counted(Path("t.xml"), cases)
    assert (report.tests, report.errors, report.failures, report.skipped) == (6, 1, 2, 1)
    assert [case.name for case in report.failed_cases] == ["failed", "errored", "not run"]
    assert [case.name for case in report.not_run_again] == ["not run"]
    assert (report.flaky_cases, report.failed) == ([flaky], True)
    assert totals([report, counted(Path("u.xml"), cases[:1])]) == {
        "tests": 7,
        "errors": 1,
        "failures": 2,
        "skipped": 1,
        "flaky": 1,
        "failed_then_not_run": 1,
    }
    assert not counted(Path("u.xml"), [cases[0], cases[4], flaky]).failed  # the control


def test_the_summary_is_in_colcons_words() -> None:
    assert summary_line(3, 1, 0, 2) == "3 tests, 1 errors, 0 failures, 2 skipped"
    assert LINE.match(f"a.xml: {summary_line(1, 0, 0, 0)}")


# --- reruns: flaky cases apart, never failures -------------------------------------------------


def _attempt(outcome: Outcome, message: str, domain: int) -> Suite:
    case = Case(
        "pkg_a.C",
        "wobbly",
        outcome=outcome,
        message=message,
        text=f"Traceback: {message}",
        type="AssertionError" if outcome is Outcome.FAILURE else "",
    )
    steady = Case("pkg_a.C", "steady")
    properties = {"ros_domain_id": str(domain)}
    return Suite("pkg_a.t", [case, steady], 1.0, validate.timestamp(), "h", properties)


@pytest.fixture
def rerun_tree(tmp_path: Path) -> Path:
    """Canonical files of two rerun tests: one flaky (failed, then passed), one always failing."""
    results = tmp_path / "results"
    results.mkdir()
    flaky = merge_attempts(
        [_attempt(Outcome.FAILURE, "late node", 3), _attempt(Outcome.PASSED, "", 5)]
    )
    (results / "flaky.xml").write_bytes(validate.render(flaky).data)
    broken = merge_attempts([_attempt(Outcome.FAILURE, f"try {n}", n) for n in (1, 2, 3)])
    (results / "broken.xml").write_bytes(validate.render(broken).data)
    return results


def test_a_flaky_pass_is_listed_apart_and_counts_as_passed(
    rerun_tree: Path, env: dict[str, str]
) -> None:
    flaky = str(rerun_tree / "flaky.xml")
    proc = run_cli(["report", flaky], env, cwd=rerun_tree)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert file_lines(proc.stdout) == {flaky: (2, 0, 0, 0)}
    assert summary_of(proc.stdout) == (2, 0, 0, 0)
    assert "Flaky: 1 case(s) passed after failing (not counted as failures):" in proc.stdout
    assert f"- pkg_a.C wobbly (1 failed attempt(s)) in {flaky}\n" in proc.stdout
    assert "pkg_a.C steady" not in proc.stdout


def test_verbose_shows_each_failed_attempt_of_a_flaky_case(
    rerun_tree: Path, env: dict[str, str]
) -> None:
    proc = run_cli(["report", "-v", str(rerun_tree / "flaky.xml")], env, cwd=rerun_tree)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "  flakyFailure: late node\n" in proc.stdout


def test_a_case_failing_every_attempt_is_a_failure_and_not_flaky(
    rerun_tree: Path, env: dict[str, str]
) -> None:
    proc = run_cli(["report", str(rerun_tree)], env, cwd=rerun_tree)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert file_lines(proc.stdout) == {
        str(rerun_tree / "broken.xml"): (2, 0, 1, 0),
        str(rerun_tree / "flaky.xml"): (2, 0, 0, 0),
    }
    assert summary_of(proc.stdout) == (4, 0, 1, 0)
    flaky_section = proc.stdout.split("Flaky: ", 1)[1]
    assert "broken.xml" not in flaky_section


def test_json_lists_flaky_cases_and_every_failed_attempt(
    rerun_tree: Path, env: dict[str, str]
) -> None:
    proc = run_cli(["report", "--json", str(rerun_tree)], env, cwd=rerun_tree)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    data = json.loads(proc.stdout)
    assert data["total"] == {
        "tests": 4,
        "errors": 0,
        "failures": 1,
        "skipped": 0,
        "flaky": 1,
        "failed_then_not_run": 0,
    }
    rows = {Path(row["path"]).name: row for row in data["files"]}
    assert rows["flaky.xml"]["flaky"] == 1
    assert rows["flaky.xml"]["failed_cases"] == []
    [flaky] = rows["flaky.xml"]["flaky_cases"]
    assert (flaky["classname"], flaky["name"], flaky["outcome"]) == ("pkg_a.C", "wobbly", "passed")
    assert flaky["earlier_failures"] == [
        {"kind": "flakyFailure", "type": "AssertionError", "message": "late node"}
    ]
    assert rows["broken.xml"]["flaky"] == 0
    [failed] = rows["broken.xml"]["failed_cases"]
    assert failed["message"] == "try 3"
    assert [item["kind"] for item in failed["earlier_failures"]] == ["rerunFailure"] * 2
    assert [item["message"] for item in failed["earlier_failures"]] == ["try 1", "try 2"]


# --- a case that failed and then was not run: never a pass (issue 30, item 5) -----------------


#: What a test writes in its first attempt: ``a`` fails, ``b`` passes.
FIRST_ATTEMPT = (
    '<testsuite name="t" tests="2" failures="1"><testcase classname="C" name="a">'
    '<failure message="late node" type="AssertionError">late node</failure></testcase>'
    '<testcase classname="C" name="b"/></testsuite>\n'
)


#: Its second attempt: ``b`` passes and ``a`` is not there at all; or ``a`` passes too.
WITHOUT_A = '<testsuite name="t" tests="1"><testcase classname="C" name="b"/></testsuite>\n'


WITH_A = (
    '<testsuite name="t" tests="2"><testcase classname="C" name="a"/>'
    '<testcase classname="C" name="b"/></testsuite>\n'
)


#: sh -c: $0 state file, $1 first attempt's file or "" (none), $2 second's, $3 result file.
TWO_ATTEMPTS = (
    'if [ -e "$0" ]; then cat "$2" > "$3"; exit 0; fi; : > "$0"; '
    'if [ -n "$1" ]; then cat "$1" > "$3"; fi; exit 1'
)


def rerun(env: dict[str, str], tmp_path: Path, first: str, second: str) -> tuple[Path, int]:
    """A real test through ``run --rerun-failures 1`` that writes ``first``, then ``second``.

    ``first`` empty: the first attempt writes no result file. The merged file, run's code.
    """
    files = []
    for name, text in (("first.own", first), ("second.own", second)):
        (tmp_path / name).write_text(text)
        files.append(str(tmp_path / name) if text else "")
    result = tmp_path / "out" / "t.xml"
    command = ["sh", "-c", TWO_ATTEMPTS, str(tmp_path / "state"), *files, str(result)]
    args = ["run", "--package-name", "pkg_a", "--rerun-failures", "1", "--junit-xml", str(result)]
    proc = run_cli([*args, "--", *command], env, cwd=tmp_path)
    assert "attempt 2 of 2: attempt 1 failed" in proc.stdout, proc.stdout + proc.stderr
    assert result.is_file(), proc.stdout + proc.stderr
    return result, proc.returncode


def test_a_case_that_failed_and_then_was_not_run_is_a_failure_named_so(
    env: dict[str, str], tmp_path: Path
) -> None:
    """It was never seen to pass: the run, the file and report all say failed, never flaky."""
    result, code = rerun(env, tmp_path, FIRST_ATTEMPT, WITHOUT_A)
    assert code == 1
    proc = run_cli(["report", str(result)], env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert file_lines(proc.stdout) == {str(result): (2, 0, 1, 0)}
    assert (
        "Failed, then not run: 1 case(s) failed and no later attempt ran them "
        "(counted as failures):\n"
        f"- pkg_a.C a (1 failed attempt(s), then not run) in {result}\n"
    ) in proc.stdout
    assert "Flaky" not in proc.stdout and "passed after failing" not in proc.stdout
    verbose = run_cli(["report", "-v", str(result)], env, cwd=tmp_path)
    assert "- pkg_a.C a (failure)\n  Failed, then not run: failure in attempt 1" in verbose.stdout
    assert "  rerunFailure: late node\n" in verbose.stdout
    as_json = run_cli(["report", "--json", str(result)], env, cwd=tmp_path)
    assert as_json.returncode == 1, as_json.stdout + as_json.stderr
    data = json.loads(as_json.stdout)
    assert data["total"]["failures"] == 1 and data["total"]["failed_then_not_run"] == 1
    (row,) = data["files"]
    assert (row["failed_then_not_run"], row["flaky"], row["flaky_cases"]) == (1, 0, [])
    (case,) = row["failed_cases"]
    assert (case["name"], case["outcome"], case["failed_then_not_run"]) == ("a", "failure", True)
    assert case["message"].startswith("Failed, then not run: ")
    assert case["earlier_failures"] == [
        {"kind": "rerunFailure", "type": "AssertionError", "message": "late node"}
    ]
    # Every other reader sees a failure too: the file itself says so.
    root = etree.parse(str(result)).getroot()
    suite = root.find("testsuite")
    assert suite is not None and suite.get("failures") == "1"
    [failure] = [node for node in root.iter("failure") if node.get("type") == NOT_RUN_AGAIN_TYPE]
    following = failure.getnext()
    assert following is not None and following.tag == "rerunFailure"
    assert root.find(".//flakyFailure") is None


def test_control_the_failed_case_passing_in_the_rerun_is_a_flaky_pass(
    env: dict[str, str], tmp_path: Path
) -> None:
    result, code = rerun(env, tmp_path, FIRST_ATTEMPT, WITH_A)
    assert code == 0
    proc = run_cli(["report", str(result)], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Flaky: 1 case(s) passed after failing (not counted as failures):\n" in proc.stdout
    assert f"- pkg_a.C a (1 failed attempt(s)) in {result}\n" in proc.stdout
    assert "Failed, then not run" not in proc.stdout
    data = json.loads(run_cli(["report", "--json", str(result)], env, cwd=tmp_path).stdout)
    assert data["total"]["failed_then_not_run"] == 0 and data["total"]["flaky"] == 1


def test_control_the_runners_own_case_of_a_failed_attempt_is_answered_by_the_rerun(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Attempt 1 wrote no file (as a test that timed out): its case is the runner's, not a test's.

    The rerun ran the whole test and it passed: what attempt 1 was is kept, as skipped
    after failing, and the run passes.
    """
    result, code = rerun(env, tmp_path, "", WITHOUT_A)
    assert code == 0
    proc = run_cli(["report", str(result)], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert file_lines(proc.stdout) == {str(result): (2, 0, 0, 1)}
    assert "Flaky: 1 case(s) skipped after failing (not counted as failures):\n" in proc.stdout
    assert f"- pkg_a.t t (1 failed attempt(s), then skipped) in {result}\n" in proc.stdout
    assert "Failed, then not run" not in proc.stdout
