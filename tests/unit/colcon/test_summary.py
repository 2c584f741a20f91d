from __future__ import annotations

from pathlib import Path

from ros_isolated_test.colcon import summary

RESULT = """<?xml version="1.0"?>
<testsuite name="pkg.{name}" tests="1" failures="{failures}">
  <properties><property name="runner_version" value="1"/>
  <property name="ros_domain_id" value="{domain}"/></properties>
  <testcase classname="pkg" name="{name}">{failure}</testcase>
</testsuite>
"""


def _results(folder: Path, *tests: tuple[str, int, bool]) -> Path:
    folder.mkdir(parents=True)
    for name, domain, failed in tests:
        failure = '<failure message="heard another"/>' if failed else ""
        (folder / f"{name}.xml").write_text(
            RESULT.format(name=name, domain=domain, failures=int(failed), failure=failure)
        )
    return folder


def test_the_line_counts_tests_failures_and_ids_and_names_the_page(tmp_path: Path) -> None:
    first = _results(tmp_path / "a", ("one", 11, False), ("two", 12, True))
    second = _results(tmp_path / "b", ("three", 11, False))
    log = tmp_path / "log" / "test_1"
    line = summary.summarise(summary.result_paths([second, first, first]), log, {})
    page = log / summary.PAGE
    assert line == (
        f"ros-isolated-test: 3 tests run, 1 failed, 0 flaky, on 2 domain IDs; page: {page}"
    )
    assert "three" in page.read_text(encoding="utf-8")


def test_no_log_no_page(tmp_path: Path) -> None:
    folder = _results(tmp_path / "a", ("one", 3, False))
    line = summary.summarise([folder], None, {})
    assert line.startswith("ros-isolated-test: 1 tests run, 0 failed, 0 flaky, on 1 domain IDs")
    assert "no page" in line


def test_a_sharded_machine_says_its_share(tmp_path: Path) -> None:
    folder = _results(tmp_path / "a", ("one", 3, False))
    line = summary.summarise([folder], tmp_path / "log", {"ROS_ISOLATED_TEST_SHARD": "2/3"})
    assert "(this machine's share 2/3)" in line


def test_a_bad_share_is_said_not_raised(tmp_path: Path) -> None:
    line = summary.summarise([], tmp_path, {"ROS_ISOLATED_TEST_SHARD": "4/3"})
    assert line.startswith("ros-isolated-test: no summary:")


def test_missing_folders_are_left_out(tmp_path: Path) -> None:
    assert summary.result_paths([tmp_path / "gone", tmp_path]) == [tmp_path]


def test_a_session_that_ran_none_of_its_tests_adds_no_id(tmp_path: Path) -> None:
    """pytest with another machine's share: its session held ID 13 for no test."""
    folder = _results(tmp_path / "a", ("one", 3, False))
    (folder / "pytest.xml").write_text(
        '<testsuites name="pytest tests"><testsuite name="pytest" errors="0" failures="0" '
        'skipped="0" tests="0" time="0.1" timestamp="2026-01-01T00:00:00+00:00"><properties>'
        '<property name="ros_domain_id" value="13"/></properties></testsuite></testsuites>'
    )
    line = summary.summarise([folder], tmp_path / "log", {})
    assert " on 1 domain IDs;" in line, line
    # The control: a test that ran on ID 13 counts it.
    (folder / "two.xml").write_text(RESULT.format(name="two", domain=13, failures=0, failure=""))
    line = summary.summarise([folder], tmp_path / "log", {})
    assert " on 2 domain IDs;" in line, line
