"""Recording a run: every attempt once, the same results again change nothing, names kept."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

from helpers.commands import run_cli
from helpers.split_trees import pytest_file, runner_file

from ros_isolated_test.history import record, stats, store
from ros_isolated_test.text import display_text

#: Names a database must keep as they are: bidi controls, 10 kB, SQL metacharacters.
HOSTILE = [
    "test_\u202eevil\u202c_name",
    "x" * 10_000,
    "t'; DROP TABLE tests; --",
    'q" OR 1=1 /* %_ */',
]


def _all(db: Path) -> list[tuple[object, ...]]:
    with sqlite3.connect(db) as raw:
        found = raw.execute("SELECT * FROM attempts ORDER BY run, test, attempt").fetchall()
    raw.close()
    return found


def test_the_same_results_recorded_again_change_nothing(tmp_path: Path) -> None:
    runner_file(tmp_path / "run1", "pkg/a", 1.5)
    runner_file(tmp_path / "run2", "pkg/a", 2.5, started=1_790_000_100.0)
    db = tmp_path / "h.sqlite3"
    assert record.record(db, [tmp_path / "run1"]) is True
    first = _all(db)
    assert record.record(db, [tmp_path / "run1"]) is False
    assert _all(db) == first
    assert record.record(db, [tmp_path / "run2"]) is True  # control: another run is new
    assert len(_all(db)) == 2


def test_hostile_names_are_stored_and_shown_as_the_report_shows_them(
    tmp_path: Path, env: dict[str, str]
) -> None:
    pytest_file(tmp_path / "run", "pkg", {name: 0.5 for name in HOSTILE})
    db = tmp_path / "h.sqlite3"
    assert record.record_trees(db, [tmp_path / "run"]) is None
    connection = store.connect(db, write=False)
    names = {item.test for item in stats.tests(connection)}
    connection.close()
    assert names == {f"pkg/{name}" for name in HOSTILE}
    assert len(_all(db)) == len(HOSTILE)  # the DROP TABLE did nothing
    shown = run_cli(["history", "--db", str(db), "--json"], env)
    assert {item["test"] for item in json.loads(shown.stdout)} == names
    text = run_cli(["history", "--db", str(db)], env)
    for name in names:
        assert display_text(name) in text.stdout
    assert "\u202e" not in text.stdout


def test_a_rerun_test_keeps_each_attempt(tmp_path: Path) -> None:
    path = runner_file(tmp_path / "run", "pkg/flip", 1.0)
    text = path.read_text().replace(
        '<property name="runner_version"',
        '<property name="attempts" value="2"/><property name="attempt_1.exit" '
        'value="exited with code 1"/><property name="attempt_1.ros_domain_id" value="9"/>'
        '<property name="runner_version"',
    )
    path.write_text(text)
    run = record.gathered([tmp_path / "run"])
    assert [row[0] for row in run.tests["pkg/flip"]] == ["failed", "passed"]
    assert run.tests["pkg/flip"][0][2] == 9


def test_an_unusable_database_is_a_warning_naming_it(tmp_path: Path) -> None:
    runner_file(tmp_path / "run", "pkg/a", 1.0)
    bad = tmp_path / "bad.sqlite3"
    bad.write_bytes(b"\x02" * 2048)
    warning = record.record_trees(bad, [tmp_path / "run"])
    assert warning is not None and str(bad) in warning and "\n" not in warning
    assert record.record_trees(tmp_path / "good.sqlite3", [tmp_path / "run"]) is None
