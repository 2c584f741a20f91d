"""``report.counts``: what a result file counts, from its cases: every count adds up.

Each case counts once, by its final outcome, whatever came before: ``tests`` is the sum
of passed, failures, errors, flaky and skipped, in the text, the JSON and on the page
alike. A flaky case (passed after failing) is listed apart; a case that failed in every
attempt is a failure, never flaky; a case that failed and was then not run is a failure,
and one skipped after failing a skip, each counted apart too. The reruns are real runs
through ``run --rerun-failures``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.report_page import page_totals, parsed
from helpers.report_text import LINE, file_lines, summary_of
from lxml import etree

from ros_isolated_test.report.counts import KEYS, PARTS, counted, summary_line
from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE, merge_attempts
from ros_isolated_test.xunit.model import Case, Outcome, Suite

# --- the counts, from the cases: one per outcome across attempts, and they add up ------------

P, F, E, S = Outcome.PASSED, Outcome.FAILURE, Outcome.ERROR, Outcome.SKIPPED
#: Outcomes of one case in each attempt (None: not in that attempt) -> the count it goes
#: to, and the part of that count it is too (or None).
SERIES: dict[str, tuple[list[Outcome | None], str, str | None]] = {
    "passed": ([P], "passed", None),
    "failed": ([F], "failures", None),
    "error": ([E], "errors", None),
    "skipped": ([S], "skipped", None),
    "failed, then passed": ([F, P], "flaky", None),
    "error, then passed": ([E, P], "flaky", None),
    "failed twice, then passed": ([F, F, P], "flaky", None),
    "failed, then skipped": ([F, S], "skipped", "skipped_after_failing"),
    "error, then skipped": ([E, S], "skipped", "skipped_after_failing"),
    "failed, then passed, then skipped": ([F, P, S], "skipped", "skipped_after_failing"),
    "failed, then not run": ([F, None], "failures", "failed_then_not_run"),
    "error, then not run": ([E, None], "errors", "failed_then_not_run"),
    "failed every attempt": ([F, F], "failures", None),
    "error, then failed": ([E, F], "failures", None),
    "failed, then error": ([F, E], "errors", None),
    "passed, then failed": ([P, F], "failures", None),
    "skipped, then failed": ([S, F], "failures", None),
    "passed, then not run": ([P, None], "skipped", None),
    "skipped, then passed": ([S, P], "passed", None),
}


def merged(series: list[Outcome | None]) -> Suite:
    """The file of a test run once per outcome in ``series``: case ``x``, and ``steady``."""
    attempts = []
    for outcome in series:
        cases = [Case("pkg.C", "steady")]
        if outcome is P:
            cases.insert(0, Case("pkg.C", "x"))
        elif outcome is not None:
            cases.insert(0, Case.saying("pkg.C", "x", outcome, f"{outcome.value} here"))
        attempts.append(Suite("pkg.t", cases, 1.0, validate.timestamp(), "h", {}))
    return attempts[0] if len(attempts) == 1 else merge_attempts(attempts)


def adds_up(counts: dict[str, int]) -> bool:
    """Every case in exactly one count, none negative; the parts within their counts."""
    return (
        all(value >= 0 for value in counts.values())
        and counts["tests"] == sum(counts[part] for part in PARTS)
        and counts["failed_then_not_run"] <= counts["failures"] + counts["errors"]
        and counts["skipped_after_failing"] <= counts["skipped"]
    )


@pytest.mark.parametrize("name", SERIES)
def test_each_outcome_across_attempts_counts_once_and_the_counts_add_up(name: str) -> None:
    series, count, part = SERIES[name]
    report = counted(Path("t.xml"), merged(series).cases)
    expected = dict.fromkeys(KEYS, 0) | {"tests": 2, "passed": 1}  # ``steady`` passed
    expected[count] += 1
    if part is not None:
        expected[part] += 1
    assert report.as_dict() == expected
    assert adds_up(report.as_dict())
    assert report.failed == (count in ("failures", "errors"))


def test_control_the_check_sees_counts_that_do_not_add_up() -> None:
    """Today's main counted a case skipped after failing as flaky and skipped: -1 passed."""
    wrong = dict.fromkeys(KEYS, 0) | {"tests": 1, "skipped": 1, "flaky": 1, "passed": -1}
    assert not adds_up(wrong)
    assert not adds_up(dict.fromkeys(KEYS, 0) | {"tests": 2, "passed": 1})  # one missing
    assert adds_up(dict.fromkeys(KEYS, 0) | {"tests": 1, "skipped": 1})


def test_a_tree_of_every_outcome_adds_up_alike_in_text_json_and_the_page(
    env: dict[str, str], tmp_path: Path
) -> None:
    tree = tmp_path / "tree"
    tree.mkdir()
    for number, (series, _, _) in enumerate(SERIES.values()):
        (tree / f"t{number:02d}.xml").write_bytes(validate.render(merged(series)).data)
    page = tmp_path / "page.html"
    proc = run_cli(["report", "--json", "--html", str(page), str(tree)], env)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    total = json.loads(proc.stdout)["total"]
    expected = dict.fromkeys(KEYS, 0) | {"tests": 2 * len(SERIES), "passed": len(SERIES)}
    for _, count, part in SERIES.values():
        expected[count] += 1
        if part is not None:
            expected[part] += 1
    assert total == expected and adds_up(total)
    assert total["flaky"] == 3 and total["skipped_after_failing"] == 3  # the control: seen
    for row in json.loads(proc.stdout)["files"]:
        assert adds_up({key: row[key] for key in KEYS}), row
    shown = page_totals(parsed(page.read_text(encoding="utf-8")))
    assert shown == {key.replace("_", " "): value for key, value in total.items() if value}
    text = run_cli(["report", str(tree)], env)
    assert summary_of(text.stdout) == (
        total["tests"],
        total["errors"],
        total["failures"],
        total["skipped"],
    )
    assert (
        f"Flaky: {total['flaky']} case(s) passed after failing, "
        f"{total['skipped_after_failing']} case(s) skipped after failing"
    ) in text.stdout
    assert f"Failed, then not run: {total['failed_then_not_run']} case(s)" in text.stdout


def test_the_summary_is_in_colcons_words() -> None:
    assert summary_line(3, 1, 0, 2) == "3 tests, 1 errors, 0 failures, 2 skipped"
    assert LINE.match(f"a.xml: {summary_line(1, 0, 0, 0)}")


#: A pytest file whose cases fail in the first attempt (the state folder is empty) and
#: then pass or skip: ``{state}`` is the folder, made fresh for the run.
PYTEST_FILE = """
import pathlib
import pytest

STATE = pathlib.Path({state!r})


def _first(name):
    marker = STATE / name
    if marker.exists():
        return False
    marker.touch()
    return True


def test_flaky():
    assert not _first("flaky"), "the first attempt fails"


def test_passing():
    pass


def test_skipped_after_failing():
    assert not _first("skip"), "the first attempt fails"
    pytest.skip("the rerun skips")
"""


def test_a_real_rerun_of_pytest_counts_the_flaky_the_passing_and_the_skipped_after_failing(
    env: dict[str, str], tmp_path: Path
) -> None:
    """``run --rerun-failures 1`` over pytest: 1 passed, 1 flaky, 1 skipped (after failing)."""
    state = tmp_path / "state"
    state.mkdir()
    (tmp_path / "test_three.py").write_text(PYTEST_FILE.format(state=str(state)))
    result = tmp_path / "results" / "pkg_a" / "three.xml"
    args = ["run", "--package-name", "pkg_a", "--rerun-failures", "1", "--junit-xml"]
    pytest_args = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "test_three.py"]
    proc = run_cli(
        [*args, str(result), "--", *pytest_args, f"--junitxml={result}"], env, cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "attempt 2 of 2: attempt 1 failed" in proc.stdout, proc.stdout
    page = tmp_path / "page.html"
    as_json = run_cli(["report", "--json", "--html", str(page), str(result)], env)
    assert as_json.returncode == 0, as_json.stdout + as_json.stderr
    total = json.loads(as_json.stdout)["total"]
    assert total == dict.fromkeys(KEYS, 0) | {
        "tests": 3,
        "passed": 1,
        "flaky": 1,
        "skipped": 1,
        "skipped_after_failing": 1,
    }
    assert page_totals(parsed(page.read_text(encoding="utf-8"))) == {
        "tests": 3,
        "passed": 1,
        "flaky": 1,
        "skipped": 1,
        "skipped after failing": 1,
    }
    text = run_cli(["report", str(result)], env)
    assert summary_of(text.stdout) == (3, 0, 0, 1)
    assert (
        "Flaky: 1 case(s) passed after failing, 1 case(s) skipped after failing "
        "(not counted as failures):"
    ) in text.stdout


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
    assert data["total"] == dict.fromkeys(KEYS, 0) | {
        "tests": 4,
        "passed": 2,
        "failures": 1,
        "flaky": 1,
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
