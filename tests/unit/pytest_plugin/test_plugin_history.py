"""The plugin records a session into the test history where ``ROS_ISOLATED_TEST_HISTORY`` is set.

Real pytest sessions in a ROS package: each item by its identity, once (an xdist
controller records, its workers do not), after --junit-xml is written; a database that
cannot be used is one warning line and the session's exit status and file are as without
it. Each beside its control.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.pytest_sessions import project, run_pytest

HISTORY_ENV = "ROS_ISOLATED_TEST_HISTORY"
TESTS = "def test_passes():\n    pass\n\ndef test_fails():\n    assert False, 'no'\n"
NODES = {"pkg/test/test_it.py::test_passes": "P", "pkg/test/test_it.py::test_fails": "F"}


def _strips(db: Path, env: dict[str, str]) -> dict[str, str]:
    proc = run_cli(["history", "--db", str(db), "--json"], env)
    assert proc.returncode == 0, proc.stderr
    return {item["test"]: item["strip"] for item in json.loads(proc.stdout)}


def _runs(db: Path) -> int:
    with sqlite3.connect(db) as raw:
        count: int = raw.execute("SELECT count(*) FROM runs").fetchone()[0]
    raw.close()
    return count


@pytest.mark.parametrize("workers", [[], ["-n", "2"]], ids=["one-process", "xdist"])
def test_a_session_is_recorded_once_by_identity(
    tmp_path: Path, env: dict[str, str], workers: list[str]
) -> None:
    root = project(tmp_path / "pkg", TESTS)
    db = tmp_path / "history.sqlite3"
    junit = tmp_path / "results" / "pytest.xml"
    proc = run_pytest(root, {**env, HISTORY_ENV: str(db)}, *workers, f"--junit-xml={junit}", "test")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "warning" not in proc.stderr, proc.stderr
    assert _strips(db, env) == NODES
    assert _runs(db) == 1
    # Control: without the variable the same session records nothing.
    again = run_pytest(root, env, *workers, f"--junit-xml={junit}", "test")
    assert again.returncode == 1
    assert _runs(db) == 1
    assert not (root / "ros_isolated_test_history.sqlite3").exists()


def test_a_corrupt_database_is_one_warning_and_the_same_session(
    tmp_path: Path, env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg", TESTS)
    junit = tmp_path / "results" / "pytest.xml"
    good = tmp_path / "good.sqlite3"
    control = run_pytest(root, {**env, HISTORY_ENV: str(good)}, f"--junit-xml={junit}", "test")
    assert control.returncode == 1 and "warning" not in control.stderr
    assert _strips(good, env) == NODES  # control: it recorded

    bad = tmp_path / "bad.sqlite3"
    bad.write_bytes(b"SQLite format 3\0" + b"\xff" * 4000)
    before = bad.read_bytes()
    proc = run_pytest(root, {**env, HISTORY_ENV: str(bad)}, f"--junit-xml={junit}", "test")
    assert proc.returncode == control.returncode
    warnings = [line for line in (proc.stdout + proc.stderr).splitlines() if "warning" in line]
    assert len(warnings) == 1 and str(bad) in warnings[0], proc.stderr
    assert warnings[0].startswith("ros-isolated-test: warning: not recorded")
    assert "Traceback" not in proc.stderr
    assert bad.read_bytes() == before
    assert "<testcase" in junit.read_text()
