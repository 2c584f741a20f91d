"""``colcon test`` records each run into the workspace's history, and its page reads it.

``summary.summarise`` as colcon's event handler calls it (the workspace is colcon's
folder): the run's result folders recorded into
``<workspace>/ros_isolated_test_history.sqlite3``, the page saying for each failure what
the runs before say; with ``ROS_ISOLATED_TEST_HISTORY`` set the runners have recorded
each test already, so the summary records nothing more and reads that database; a
database that cannot be used is one warning line before the summary line, whose page
and counts are as without it.
"""

from __future__ import annotations

import json
from pathlib import Path

from helpers.commands import run_cli
from helpers.split_trees import START, runner_file

from ros_isolated_test.colcon import summary

DB = "ros_isolated_test_history.sqlite3"


def _run(tmp_path: Path, number: int, fails: bool) -> Path:
    """Run ``number``'s result folder: pkg/stable passes, pkg/odd fails when ``fails``."""
    folder = tmp_path / f"run{number}"
    runner_file(folder, "pkg/stable", 1.0, started=START + 100 * number)
    odd = runner_file(folder, "pkg/odd", 1.0, started=START + 100 * number + 1)
    if fails:
        failed = 'time="1.000"><failure message="no">no</failure></testcase>'
        odd.write_text(odd.read_text().replace('time="1.000"/>', failed))
    return folder


def _runs(db: Path, env: dict[str, str]) -> dict[str, int]:
    proc = run_cli(["history", "--db", str(db), "--json"], env)
    assert proc.returncode == 0, proc.stderr
    return {item["test"]: item["runs"] for item in json.loads(proc.stdout)}


def test_each_run_is_recorded_and_the_page_reads_the_runs_before(
    tmp_path: Path, env: dict[str, str]
) -> None:
    workspace = tmp_path / "ws"
    workspace.mkdir()
    for number, fails in enumerate((True, False, True), start=1):
        log = workspace / "log" / f"test_{number}"
        line = summary.summarise([_run(tmp_path, number, fails)], log, {}, workspace=workspace)
        assert line.startswith("ros-isolated-test: 2 tests run") and "\n" not in line, line
    assert _runs(workspace / DB, env) == {"pkg/stable": 3, "pkg/odd": 3}
    page = (workspace / "log" / "test_3" / summary.PAGE).read_text(encoding="utf-8")
    assert "known flaky (1 of the last 2 runs failed)" in page
    assert "id=fact-history" in page
    # Control: the same run summarised again records nothing new.
    summary.summarise([tmp_path / "run3"], workspace / "log" / "again", {}, workspace=workspace)
    assert _runs(workspace / DB, env) == {"pkg/stable": 3, "pkg/odd": 3}


def test_with_the_variable_set_the_run_is_recorded_there_once_whole(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """The named database, not the workspace's, gets the run (colcon is its one recorder)."""
    workspace = tmp_path / "ws"
    workspace.mkdir()
    named = tmp_path / "named.sqlite3"
    run_cli(["history", "record", "--db", str(named), str(_run(tmp_path, 1, True))], env)
    log = workspace / "log" / "test_2"
    environ = {"ROS_ISOLATED_TEST_HISTORY": str(named)}
    summary.summarise([_run(tmp_path, 2, True)], log, environ, workspace=workspace)
    assert not (workspace / DB).exists()
    assert _runs(named, env) == {"pkg/stable": 2, "pkg/odd": 2}
    assert "new: passed its last" not in (log / summary.PAGE).read_text(encoding="utf-8")
    assert "broken since run 1" in (log / summary.PAGE).read_text(encoding="utf-8")


def test_a_corrupt_database_is_one_warning_and_the_same_summary(tmp_path: Path) -> None:
    workspace = tmp_path / "ws"
    workspace.mkdir()
    (workspace / DB).write_bytes(b"SQLite format 3\0" + b"\xff" * 4000)
    folder = _run(tmp_path, 1, True)
    line = summary.summarise([folder], workspace / "log" / "t", {}, workspace=workspace)
    warning, said = line.split("\n")
    assert warning.startswith("ros-isolated-test: warning: not recorded in the history")
    assert str(workspace / DB) in warning
    control = summary.summarise([folder], tmp_path / "log" / "t", {})
    assert said.replace(str(workspace / "log"), str(tmp_path / "log")) == control
