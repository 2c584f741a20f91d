"""``report.shard``: a split's trees merged, and every way the merge can fall short, named.

The machines' trees (``helpers.split_trees``: what the runners and the plugin leave) are
read as ``report`` reads them. A complete split says nothing wrong; a missing share, two
plans, a test run twice, a producer's file in several trees or a share's session that
started and left no results is one line each, beside its control. The page shows the
problems first and a group of timeline rows per machine.
"""

from __future__ import annotations

from pathlib import Path

from helpers.report_page import parsed, timeline_rows
from helpers.split_trees import runner_file, split_trees

from ros_isolated_test.report import html_report
from ros_isolated_test.report.shard import Split
from ros_isolated_test.report.tree import read_tree
from ros_isolated_test.shard import record
from ros_isolated_test.shard.durations import measured
from ros_isolated_test.shard.selection import Selection
from ros_isolated_test.shard.spec import Share

TESTS = {
    **{f"nav_{p}/test_{n}": 1.0 + n for p in range(3) for n in range(5)},
    **{f"py_pkg/test/test_{n}.py::test_case": 0.5 for n in range(6)},
}


def _split(*trees: Path, expected: Share | None = None) -> Split:
    split = Split(expected)
    records: list[Path] = []
    for item in read_tree(trees, records):
        split.add(item)
    split.add_records(records)
    return split


def test_a_complete_split_has_no_problem_and_lists_its_shares(tmp_path: Path) -> None:
    trees = split_trees(tmp_path, TESTS, 3)
    split = _split(*trees)
    assert split.is_split and split.problems == []
    assert [(share, plan) for share, plan, _hosts in split.shares()] == [
        ("1/3", "count"), ("2/3", "count"), ("3/3", "count"),
    ]  # fmt: skip
    # The control: trees of no split say nothing at all.
    plain = tmp_path / "plain"
    for key, seconds in TESTS.items():
        if "::" not in key:
            runner_file(plain, key, seconds)
    assert not _split(plain).is_split and _split(plain).problems == []


def test_a_missing_share_is_named_and_one_that_ran_nothing_is_not(tmp_path: Path) -> None:
    trees = split_trees(tmp_path, {"a/t1": 1.0}, 4)  # three shares run nothing
    assert _split(*trees).problems == []
    (problem,) = _split(trees[0], trees[1], trees[3]).problems
    assert problem.startswith(
        "shard 3 of 4 left no results (no record ros_isolated_test_shard-3-of-4.json"
    )


def test_a_started_record_with_no_result_beside_it_is_named(tmp_path: Path) -> None:
    """A pytest session of share 1 died before writing its file; the control: a started
    record whose session did write it (killed after) is no problem."""
    trees = split_trees(tmp_path, TESTS, 2)
    folder = trees[0] / "py_pkg"
    record.leave(folder, Selection(Share(1, 2), None), "machine-1", "0.1.0", started=True)
    assert _split(*trees).problems == []
    (folder / "pytest.xml").unlink()
    (problem,) = _split(*trees).problems
    assert problem.startswith(
        f"shard 1 of 2 started and left no results in {folder} (its record "
        "ros_isolated_test_shard-1-of-2.json says started"
    )


def test_a_machines_own_report_expects_its_share_alone(tmp_path: Path) -> None:
    trees = split_trees(tmp_path, TESTS, 3)
    assert _split(trees[1], expected=Share(2, 3)).problems == []
    (problem,) = _split(trees[0], expected=Share(2, 3)).problems
    assert problem.startswith("shard 2 of 3 left no results")


def test_shares_under_different_plans_are_named(tmp_path: Path) -> None:
    old = measured({key: 1.0 for key in TESTS})
    new = measured({**{key: 1.0 for key in TESTS}, "nav_0/test_0": 30.0})
    first = split_trees(tmp_path / "old", TESTS, 2, old)
    second = split_trees(tmp_path / "new", TESTS, 2, new)
    problems = _split(first[0], second[1]).problems
    assert any(
        line.startswith(
            f"the shards ran under different plans (1/2 under plan {old.fingerprint}; "
            f"2/2 under plan {new.fingerprint})"
        )
        for line in problems
    ), problems
    # The control: both shares of one plan.
    assert _split(*second).problems == []


def test_a_test_run_in_two_shares_or_counted_twice_is_named(tmp_path: Path) -> None:
    trees = split_trees(tmp_path, TESTS, 2)
    assert _split(*trees).problems == []
    for index, tree in enumerate(trees, start=1):
        runner_file(tree, "nav_0/test_extra", 1.0, Selection(Share(index, 2), None))
    (problem,) = _split(*trees).problems
    assert problem == (
        "test nav_0/test_extra ran in shard 1/2 and shard 2/2: each test must run in one share only"
    )
    twice = _split(trees[0], trees[0]).problems
    assert any("results of shard 1/2 (a tree given twice?)" in line for line in twice), twice


def test_another_producers_file_in_every_tree_is_named(tmp_path: Path) -> None:
    """A test not run through our RUNNER or plugin runs on every machine."""
    trees = split_trees(tmp_path, TESTS, 2)
    assert _split(*trees).problems == []
    for tree in trees:
        lint = tree / "nav_0" / "test_results" / "nav_0" / "lint.xunit.xml"
        lint.write_text('<testsuite name="lint" tests="1"><testcase name="flake8"/></testsuite>')
    (problem,) = _split(*trees).problems
    assert problem.startswith("nav_0/lint.xunit.xml (a result file of another producer, which")


def test_the_page_names_the_problems_first_and_a_row_group_per_machine(tmp_path: Path) -> None:
    trees = split_trees(tmp_path, TESTS, 3)
    page_file = tmp_path / "page.html"
    html_report.write(trees, page_file, split=Split())
    page = parsed(page_file.read_text())
    assert not page.xpath("//*[@id='split-problems']")
    assert page.xpath("//header//h1")[0].text == "PASSED"
    machines = {row.get("data-machine") for row in timeline_rows(page)}
    assert machines == {f"shard {index}/3 · machine-{index}" for index in (1, 2, 3)}
    assert "1/3 (plan count, on machine-1)" in page.xpath("//*[@id='fact-shards']")[0].text
    # Without share 2: the page fails and says why, first.
    html_report.write([trees[0], trees[2]], page_file, split=Split())
    page = parsed(page_file.read_text())
    assert page.xpath("//header//h1")[0].text == "FAILED"
    (problem,) = page.xpath("//*[@id='split-problems']//li")
    assert problem.text.startswith("shard 2 of 3 left no results")
