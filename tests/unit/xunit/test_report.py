"""``xunit.report``: a tree of result files summarised, counted from the cases, as real processes.

``ros-isolated-test report`` reads canonical and raw producer files alike, through the
reader and normaliser the runner uses, so its counts are the ones a canonical file of
it would carry; colcon's line per file, the summary last. A flaky case counts as
passed and is listed apart; a case that failed and was then not run is a failure,
listed apart too; a folder that cannot be read is an error, never a quiet gap; a file
name cannot forge a line. Run as the CLI, as users run it, on real trees.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import run_cli
from helpers.processes import user_keywords
from helpers.xunit import SAMPLES
from lxml import etree

from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE, merge_attempts
from ros_isolated_test.xunit.model import Attempt, Case, Outcome, Suite
from ros_isolated_test.xunit.report import counted, summary_line, totals

RESULTS = Path("build/pkg_a/test_results/pkg_a")


LINE = re.compile(r"^(?P<path>.+): (\d+) tests, (\d+) errors, (\d+) failures, (\d+) skipped$")


SUMMARY = re.compile(r"^Summary: (\d+) tests, (\d+) errors, (\d+) failures, (\d+) skipped$")


CTEST_SITE = (
    '<?xml version="1.0" encoding="UTF-8"?>\n<Site BuildName="Linux" Name="vm">'
    '<Testing><TestList><Test>./t</Test></TestList><Test Status="failed"><Name>t</Name>'
    "</Test></Testing></Site>\n"
)


Counts = tuple[int, int, int, int]


"""(tests, errors, failures, skipped), the order of colcon's line."""


@dataclass(frozen=True)
class Tree:
    root: Path
    expected: dict[str, Counts]
    """Counts of each file report must list, by path relative to ``root``."""


def failed_cases_of(sample: Path) -> list[tuple[str, str, str, str]]:
    """(classname, name, outcome, message) of each failing case, read from the raw sample."""
    found = []
    for case in etree.parse(str(sample)).getroot().iter("testcase"):
        for child in case:
            if child.tag in ("failure", "error"):
                found.append(
                    (
                        case.get("classname", ""),
                        case.get("name", ""),
                        str(child.tag),
                        child.get("message", ""),
                    )
                )
    return found


def canonical_run(env: dict[str, str], cwd: Path, result: Path, script: str) -> None:
    """A canonical file written by ``run --junit-xml`` for a real command."""
    proc = run_cli(
        ["run", "--package-name", "pkg_a", "--junit-xml", str(result), "--", "sh", "-c", script],
        env,
        cwd=cwd,
    )
    assert result.is_file(), proc.stdout + proc.stderr


@pytest.fixture
def tree(env: dict[str, str], tmp_path: Path) -> Tree:
    """A colcon build tree: canonical and raw files, a ctest Test.xml, broken and hidden ones."""
    root = tmp_path / "ws"
    results = root / RESULTS
    results.mkdir(parents=True)
    canonical_run(env, root, results / "talker.xml", "echo fine")
    canonical_run(env, root, results / "crash.xml", "echo boom-marker; exit 4")
    shutil.copy(SAMPLES / "pytest-9.2_xunit2.xml", results / "pytest_raw.xml")
    proc = run_cli(
        [
            "normalise",
            "--package-name",
            "pkg_a",
            str(SAMPLES / "pytest-9.2_xunit2.xml"),
            "-o",
            str(results / "pytest_canonical.xml"),
        ],
        env,
        cwd=root,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    shutil.copy(SAMPLES / "ament_run_test_skip_result.xml", results / "skipped_raw.xml")
    (results / "broken.xml").write_text("this is not xml\n")
    testing = root / "build/pkg_a/Testing/20260101-0000"
    testing.mkdir(parents=True)
    (testing / "Test.xml").write_text(CTEST_SITE)
    for hidden in (root / "build/.hidden", root / "build/pkg_a/.colcon"):
        hidden.mkdir(parents=True)
        shutil.copy(SAMPLES / "ament_run_test_missing_result.xml", hidden / "stale.xml")
    expected = {
        f"{RESULTS}/talker.xml": (1, 0, 0, 0),
        f"{RESULTS}/crash.xml": (1, 0, 1, 0),
        # The counts colcon reports for this sample (xunit-formats.md, section 3).
        f"{RESULTS}/pytest_raw.xml": (12, 2, 2, 3),
        f"{RESULTS}/pytest_canonical.xml": (12, 2, 2, 3),
        f"{RESULTS}/skipped_raw.xml": (1, 0, 0, 1),
        f"{RESULTS}/broken.xml": (1, 1, 0, 0),
    }
    return Tree(root, expected)


def file_lines(stdout: str) -> dict[str, Counts]:
    found: dict[str, Counts] = {}
    for line in stdout.splitlines():
        match = LINE.match(line)
        if match and not line.startswith("Summary: "):
            path, *counts = match.groups()
            assert path not in found, f"{path} listed twice"
            found[path] = (int(counts[0]), int(counts[1]), int(counts[2]), int(counts[3]))
    return found


def summary_of(stdout: str) -> Counts:
    lines = [line for line in stdout.splitlines() if line.strip()]
    match = SUMMARY.match(lines[-1])
    assert match, f"last line is not the summary:\n{stdout}"
    tests, errors, failures, skipped = (int(value) for value in match.groups())
    return tests, errors, failures, skipped


def total(counts: list[Counts]) -> Counts:
    return (
        sum(item[0] for item in counts),
        sum(item[1] for item in counts),
        sum(item[2] for item in counts),
        sum(item[3] for item in counts),
    )


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


# --- the summary -------------------------------------------------------------------------------


def test_default_path_is_build_and_every_result_file_gets_its_line(
    tree: Tree, env: dict[str, str]
) -> None:
    proc = run_cli(["report"], env, cwd=tree.root)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    # Test.xml (root <Site>) is not a result and hidden folders are skipped, as colcon does.
    assert file_lines(proc.stdout) == tree.expected
    assert "Test.xml" not in proc.stdout
    assert "stale.xml" not in proc.stdout
    assert summary_of(proc.stdout) == total(list(tree.expected.values()))


def test_raw_and_canonical_form_of_the_same_file_count_alike(
    tree: Tree, env: dict[str, str]
) -> None:
    proc = run_cli(
        ["report", str(RESULTS / "pytest_raw.xml"), str(RESULTS / "pytest_canonical.xml")],
        env,
        cwd=tree.root,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = file_lines(proc.stdout)
    assert lines[str(RESULTS / "pytest_raw.xml")] == lines[str(RESULTS / "pytest_canonical.xml")]


def test_explicit_paths_are_read_from_anywhere(
    tree: Tree, env: dict[str, str], tmp_path: Path
) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    build = tree.root / "build"
    proc = run_cli(["report", str(build)], env, cwd=elsewhere)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    expected = {str(tree.root / path): counts for path, counts in tree.expected.items()}
    assert file_lines(proc.stdout) == expected


def test_exit_code_is_zero_when_everything_passed_or_was_skipped(
    tree: Tree, env: dict[str, str], tmp_path: Path
) -> None:
    clean = tmp_path / "clean"
    results = clean / "pkg"
    results.mkdir(parents=True)
    shutil.copy(tree.root / RESULTS / "talker.xml", results / "talker.xml")
    shutil.copy(SAMPLES / "ament_run_test_skip_result.xml", results / "skipped.xml")
    shutil.copy(SAMPLES / "ament_run_test_success_result.xml", results / "success.xml")
    (results / "Test.xml").write_text(CTEST_SITE)
    # A failing file in a hidden folder must not count.
    (clean / ".old").mkdir()
    shutil.copy(SAMPLES / "ament_run_test_missing_result.xml", clean / ".old" / "failed.xml")
    proc = run_cli(["report", str(clean)], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert file_lines(proc.stdout) == {
        f"{results}/skipped.xml": (1, 0, 0, 1),
        f"{results}/success.xml": (1, 0, 0, 0),
        f"{results}/talker.xml": (1, 0, 0, 0),
    }
    assert summary_of(proc.stdout) == (3, 0, 0, 1)


def test_only_a_ctest_site_file_is_nothing_to_report(env: dict[str, str], tmp_path: Path) -> None:
    (tmp_path / "Test.xml").write_text(CTEST_SITE)
    proc = run_cli(["report", str(tmp_path)], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert file_lines(proc.stdout) == {}
    assert summary_of(proc.stdout) == (0, 0, 0, 0)


def test_a_broken_file_alone_fails_the_report(env: dict[str, str], tmp_path: Path) -> None:
    (tmp_path / "cut.xml").write_text(
        '<testsuites><testsuite name="s" tests="1"><testcase classname="C" name="ok"/>'
    )
    proc = run_cli(["report", str(tmp_path)], env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    # The case before the damage is kept; the damage is one error.
    assert file_lines(proc.stdout) == {f"{tmp_path}/cut.xml": (2, 1, 0, 0)}


# --- --verbose and --json ----------------------------------------------------------------------


def test_verbose_lists_each_failing_case_with_classname_name_and_message(
    tree: Tree, env: dict[str, str]
) -> None:
    proc = run_cli(["report", "--verbose"], env, cwd=tree.root)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    out = proc.stdout
    assert file_lines(out) == tree.expected
    assert "- pkg_a.crash crash (failure)\n" in out
    crash = out.split("- pkg_a.crash crash (failure)\n", 1)[1]
    assert "exited with code 4" in crash.split("\n- ", 1)[0]
    assert "boom-marker" in crash.split("\n- ", 1)[0]
    failing = failed_cases_of(SAMPLES / "pytest-9.2_xunit2.xml")
    assert len(failing) == 4
    for classname, name, outcome, message in failing:
        head = f"- {classname} {name} ({outcome})\n"
        assert head in out, f"{head!r} missing from:\n{out}"
        assert f"{head}  {message.splitlines()[0]}\n" in out
    assert "- broken result file (error)\n  Invalid result file broken.xml" in out
    # Passing and skipped cases are not listed.
    assert "- pkg_a.talker" not in out
    listed = [line for line in out.splitlines() if line.startswith("- ")]
    assert len(listed) == sum(
        errors + failures for _, errors, failures, _ in tree.expected.values()
    )


def test_json_has_the_same_numbers_and_the_failed_cases(tree: Tree, env: dict[str, str]) -> None:
    plain = run_cli(["report"], env, cwd=tree.root)
    proc = run_cli(["report", "--json"], env, cwd=tree.root)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    data = json.loads(proc.stdout)
    files = {
        row["path"]: (row["tests"], row["errors"], row["failures"], row["skipped"])
        for row in data["files"]
    }
    assert files == file_lines(plain.stdout) == tree.expected
    totals = data["total"]
    assert (totals["tests"], totals["errors"], totals["failures"], totals["skipped"]) == (
        summary_of(plain.stdout)
    )
    assert any(row["failed_cases"] for row in data["files"]), data  # else the loop checks none
    for row in data["files"]:
        assert len(row["failed_cases"]) == row["errors"] + row["failures"], row
        for case in row["failed_cases"]:
            assert set(case) >= {"classname", "name", "outcome", "message"}
            assert case["outcome"] in ("failure", "error")
            assert case["message"], case
    by_path = {row["path"]: row for row in data["files"]}
    [crash] = by_path[f"{RESULTS}/crash.xml"]["failed_cases"]
    assert (crash["classname"], crash["name"], crash["outcome"]) == (
        "pkg_a.crash",
        "crash",
        "failure",
    )
    assert "exited with code 4" in crash["message"]
    raw = {
        (case["classname"], case["name"], case["outcome"], case["message"])
        for case in by_path[f"{RESULTS}/pytest_raw.xml"]["failed_cases"]
    }
    assert raw == set(failed_cases_of(SAMPLES / "pytest-9.2_xunit2.xml"))


def test_json_exit_code_is_zero_when_all_passed(tree: Tree, env: dict[str, str]) -> None:
    proc = run_cli(["report", "--json", str(RESULTS / "talker.xml")], env, cwd=tree.root)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    data = json.loads(proc.stdout)
    assert data["total"] == {
        "tests": 1,
        "errors": 0,
        "failures": 0,
        "skipped": 0,
        "flaky": 0,
        "failed_then_not_run": 0,
    }
    assert data["files"][0]["failed_cases"] == []
    assert data["files"][0]["flaky_cases"] == []


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


# --- a folder report cannot read (issue 30, item 4) --------------------------------------------


def readable_tree(root: Path) -> tuple[Path, Path]:
    """``tree/ok.xml`` passing and ``tree/sub/f.xml`` failing, every user may read them."""
    tree, sub = root / "tree", root / "tree" / "sub"
    sub.mkdir(parents=True)
    shutil.copy(SAMPLES / "ament_run_test_success_result.xml", tree / "ok.xml")
    shutil.copy(SAMPLES / "ament_run_test_missing_result.xml", sub / "f.xml")
    for path, mode in ((tree, 0o755), (sub, 0o755), (tree / "ok.xml", 0o644)):
        os.chmod(path, mode)
    os.chmod(sub / "f.xml", 0o644)
    return tree, sub


def as_nobody(args: list[str], env: dict[str, str]) -> tuple[int, str]:
    proc = run_cli(args, env, **user_keywords(65534))
    return proc.returncode, proc.stdout + proc.stderr


@capabilities.OTHER_USERS
def test_control_a_readable_tree_reports_the_failure_in_its_sub_folder(
    traversable_dir: Path, env: dict[str, str]
) -> None:
    tree, sub = readable_tree(traversable_dir)
    code, out = as_nobody(["report", str(tree)], env)
    assert code == 1, out
    assert file_lines(out) == {f"{tree}/ok.xml": (1, 0, 0, 0), f"{sub}/f.xml": (1, 1, 0, 0)}


@capabilities.OTHER_USERS
@pytest.mark.parametrize("mode", [0o700, 0o711], ids=["no-access", "enter-only"])
def test_a_folder_report_cannot_list_is_an_error_naming_it(
    traversable_dir: Path, env: dict[str, str], mode: int
) -> None:
    tree, sub = readable_tree(traversable_dir)
    os.chmod(sub, mode)
    code, out = as_nobody(["report", "-v", str(tree)], env)
    assert code == 1, out
    assert file_lines(out) == {f"{tree}/ok.xml": (1, 0, 0, 0), str(sub): (1, 1, 0, 0)}
    assert summary_of(out) == (2, 1, 0, 0)
    assert (
        f"- sub result folder (error)\n  Cannot read the result folder {sub}: Permission denied;"
    ) in out
    code, out = as_nobody(["report", "--json", str(tree)], env)
    assert code == 1, out
    rows = {row["path"]: row for row in json.loads(out)["files"]}
    [case] = rows[str(sub)]["failed_cases"]
    assert (case["name"], case["outcome"]) == ("result folder", "error")
    assert str(sub) in case["message"]


@capabilities.OTHER_USERS
def test_a_folder_report_can_list_but_not_enter_fails_on_each_file_it_holds(
    traversable_dir: Path, env: dict[str, str]
) -> None:
    """Its names are known, nothing in it can be opened: each file and folder is an error."""
    tree, sub = readable_tree(traversable_dir)
    (sub / "deeper").mkdir()
    os.chmod(sub, 0o744)
    code, out = as_nobody(["report", "-v", str(tree)], env)
    assert code == 1, out
    assert file_lines(out) == {
        f"{tree}/ok.xml": (1, 0, 0, 0),
        f"{sub}/f.xml": (1, 1, 0, 0),
        f"{sub}/deeper": (1, 1, 0, 0),
    }
    assert "cannot open the result file: Permission denied" in out
    assert f"Cannot read the result folder {sub}/deeper: Permission denied;" in out


# --- hostile file names (issue 30, item 8) -----------------------------------------------------


def test_a_file_name_cannot_forge_a_line_of_the_report(env: dict[str, str], tmp_path: Path) -> None:
    """Control characters and undecodable bytes are shown as ``status`` shows them."""
    folder = tmp_path / "results"
    folder.mkdir()
    forged = "a.xml: 0 tests, 0 errors, 0 failures, 0 skipped\nb.xml"
    (folder / forged).write_text("this is not xml\n")  # an error case named after the file
    styled = os.fsdecode(b"c\xff\x1b[31m.xml")
    shutil.copy(SAMPLES / "ament_run_test_success_result.xml", folder / styled)
    shutil.copy(SAMPLES / "ament_run_test_success_result.xml", folder / "plain.xml")
    proc = run_cli(["report", str(folder)], env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    shown_forged = "a.xml: 0 tests, 0 errors, 0 failures, 0 skipped\\x0ab.xml"
    assert file_lines(proc.stdout) == {
        f"{folder}/{shown_forged}": (1, 1, 0, 0),
        f"{folder}/c\\xff\\x1b[31m.xml": (1, 0, 0, 0),
        f"{folder}/plain.xml": (1, 0, 0, 0),  # the control: a plain name as it is
    }
    assert summary_of(proc.stdout) == (3, 1, 0, 0)
    assert len(proc.stdout.splitlines()) == 5  # three files, a blank line, the summary
    # -v: the case named after the file is one line too; messages are indented under it.
    verbose = run_cli(["report", "-v", str(folder)], env, cwd=tmp_path).stdout
    own_lines = [line for line in verbose.splitlines() if not line.startswith("  ")]
    assert not [line for line in own_lines if line.startswith("b")], verbose
    assert "- a.xml: 0 tests, 0 errors, 0 failures, 0 skipped\\x0ab result file (error)\n" in (
        verbose
    )
    # JSON carries each path exactly (its escapes are JSON's): each can be opened.
    data = json.loads(run_cli(["report", "--json", str(folder)], env, cwd=tmp_path).stdout)
    assert sorted(row["path"] for row in data["files"]) == sorted(
        str(folder / name) for name in (forged, styled, "plain.xml")
    )


# --- usage errors ------------------------------------------------------------------------------


def test_no_build_folder_and_no_path_is_a_usage_error(env: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(["report"], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Usage: ros-isolated-test report" in proc.stderr
    assert "no 'build' folder" in proc.stderr
    assert "Summary" not in proc.stdout


def test_nonexistent_path_is_a_usage_error(env: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(["report", str(tmp_path / "no-such-folder")], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "no-such-folder" in proc.stderr
    assert "does not exist" in proc.stderr
    assert "Summary" not in proc.stdout
