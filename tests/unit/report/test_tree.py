"""``report.tree``: the result files under the paths given, each read and counted once.

The default path is ``build``; canonical and raw files count alike; XML that is no
result (ctest's Test.xml) and hidden folders are skipped, as colcon does; a broken file
or a folder that cannot be read is an error, never a quiet gap. Run as the CLI, as users
run it, on real trees.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import run_cli, the_error_line
from helpers.processes import user_keywords
from helpers.report_text import (
    CTEST_SITE,
    RESULTS,
    Tree,
    file_lines,
    summary_of,
    total,
)
from helpers.xunit import SAMPLES

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


# --- usage errors ------------------------------------------------------------------------------


def test_no_build_folder_and_no_path_is_a_usage_error(env: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(["report"], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    line = the_error_line(proc)  # one line, as every usage error (cli.usage)
    assert "no 'build' folder" in line and line.endswith("see ros-isolated-test report --help")
    assert "Summary" not in proc.stdout


def test_nonexistent_path_is_a_usage_error(env: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(["report", str(tmp_path / "no-such-folder")], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "no-such-folder" in proc.stderr
    assert "does not exist" in proc.stderr
    assert "Summary" not in proc.stdout


# --- a split's trees -----------------------------------------------------------------------------


def test_a_share_that_held_none_of_a_packages_tests_counts_none(
    env: dict[str, str], tmp_path: Path
) -> None:
    """pytest's file of a share whose items all went elsewhere: nothing ran there, by design.
    The control: a file of no cases that names no share is one skip saying so."""
    empty = '<testsuites><testsuite name="pytest" tests="0">{}</testsuite></testsuites>'
    share = '<properties><property name="shard" value="2/3"/></properties>'
    (tmp_path / "split" / "pkg").mkdir(parents=True)
    (tmp_path / "split" / "pkg" / "pytest.xml").write_text(empty.format(share))
    (tmp_path / "plain" / "pkg").mkdir(parents=True)
    (tmp_path / "plain" / "pkg" / "pytest.xml").write_text(empty.format(""))
    split = run_cli(["report", str(tmp_path / "split")], {**env, "ROS_ISOLATED_TEST_SHARD": "2/3"})
    assert "Summary: 0 tests, 0 errors, 0 failures, 0 skipped" in split.stdout, split.stdout
    plain = run_cli(["report", str(tmp_path / "plain")], env)
    assert "Summary: 1 tests, 0 errors, 0 failures, 1 skipped" in plain.stdout, plain.stdout


def test_the_records_of_a_split_are_found_and_never_read_as_results(tmp_path: Path) -> None:
    from ros_isolated_test.report.tree import result_files

    folder = tmp_path / "pkg" / "test_results" / "pkg"
    folder.mkdir(parents=True)
    (folder / "t.xml").write_text("<testsuite/>")
    (folder / "ros_isolated_test_shard-1-of-2.json").write_text("{}")
    (folder / "other.json").write_text("{}")
    records: list[Path] = []
    assert list(result_files([tmp_path], records)) == [folder / "t.xml"]
    assert records == [folder / "ros_isolated_test_shard-1-of-2.json"]
    given: list[Path] = []
    assert list(result_files([folder / "ros_isolated_test_shard-1-of-2.json"], given)) == []
    assert given == [folder / "ros_isolated_test_shard-1-of-2.json"]
