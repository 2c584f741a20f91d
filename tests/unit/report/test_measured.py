"""``report.measured``: which tests a result file holds by identity, and how long each took.

A RUNNER's file is its ctest test (its ``duration``), pytest's file under the plugin is
its named items (their times); anything else names no test. Several runs merge into the
median, a split's shards into their union.
"""

from __future__ import annotations

from pathlib import Path

from helpers.split_trees import pytest_file, runner_file, split_trees

from ros_isolated_test.report.measured import Gathered, named_tests
from ros_isolated_test.report.tree import read_file, read_tree
from ros_isolated_test.shard.durations import measured
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.model import Case, Suite


def _tests(path: Path) -> list[tuple[str, float | None]]:
    item = read_file(path)
    assert item is not None
    return named_tests(item)


def test_a_runner_file_is_its_ctest_test_and_its_duration(tmp_path: Path) -> None:
    path = runner_file(tmp_path, "nav2_util/test_lifecycle", 12.5)
    assert _tests(path) == [("nav2_util/test_lifecycle", 12.5)]


def test_pytest_items_are_named_by_their_property(tmp_path: Path) -> None:
    path = pytest_file(tmp_path, "py_pkg", {"test/test_a.py::test_x": 0.25, "test/t.py::T::y": 2})
    assert sorted(_tests(path)) == [
        ("py_pkg/test/t.py::T::y", 2.0),
        ("py_pkg/test/test_a.py::test_x", 0.25),
    ]


def test_a_file_naming_no_test_a_split_places_gives_none(tmp_path: Path) -> None:
    """Another producer's file (no runner_version, no identity property) names none; so
    does a runner's file of a test that was not run (it measured nothing)."""
    other = tmp_path / "other.xml"
    other.write_bytes(
        serialise.serialize(
            Suite("pkg.t", [Case("pkg.t", "t", 1.0)], 1.0, "2026-01-01T00:00:00", "h")
        )
    )
    assert _tests(other) == []
    not_run = runner_file(tmp_path, "pkg/t", 3.0)
    not_run.write_text(not_run.read_text().replace("exited with code 0", "not run"))
    assert _tests(not_run) == [("pkg/t", None)]


def test_runs_merge_into_the_median_and_shards_into_their_union(tmp_path: Path) -> None:
    tests = {"a/t1": 10.0, "a/t2": 1.0, "b/test/x.py::test_y": 0.5, "b/test/x.py::test_z": 3.0}
    gathered = Gathered()
    for item in read_tree(split_trees(tmp_path / "run1", tests, 3)):
        gathered.add(item)
    assert gathered.durations() == measured(tests)  # the shards: their union
    slower = {key: seconds * 3 for key, seconds in tests.items()}
    for run, times in (("run2", slower), ("run3", tests)):
        for item in read_tree(split_trees(tmp_path / run, times, 2)):
            gathered.add(item)
    # Each test measured three times: 1x, 3x, 1x: the median is 1x.
    assert gathered.durations() == measured(tests)
