"""``report.text_report``: colcon's line per file, ``--verbose``'s failures, ``--json``.

``--verbose`` lists each failing case with its message; ``--json`` has the same
numbers and every failed case; a file name cannot forge a line. Run as the CLI.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from helpers.commands import run_cli
from helpers.report_text import (
    RESULTS,
    Tree,
    failed_cases_of,
    file_lines,
    summary_of,
)
from helpers.xunit import SAMPLES

from ros_isolated_test.report.counts import KEYS

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
    assert data["total"] == dict.fromkeys(KEYS, 0) | {"tests": 1, "passed": 1}
    assert data["files"][0]["failed_cases"] == []
    assert data["files"][0]["flaky_cases"] == []


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
