"""A split planned from the test history itself: the same plan as from ``history durations``.

``shard --plan --durations DB``, ``ROS_ISOLATED_TEST_DURATIONS=DB`` under the RUNNER and
``load(DB)`` all read the database as the file ``history durations FILE`` writes from it;
a foreign SQLite file is refused in one line, and a JSON file is read as before.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from helpers.commands import ament, run_cli, the_error_line
from helpers.results import load_result
from helpers.split_trees import START, runner_file

from ros_isolated_test.history import record, store
from ros_isolated_test.shard.durations import (
    DURATIONS_ENV,
    HISTORY_APPLICATION_ID,
    DurationsError,
    load,
)
from ros_isolated_test.shard.selection import Selection
from ros_isolated_test.shard.spec import SHARD_ENV, Share

#: Each test's seconds in three runs: the median (not the mean, not the latest) counts.
RUNS = {
    "pkg/long": (90.0, 100.0, 400.0),
    "pkg/mid": (40.0, 50.0, 45.0),
    "pkg/short_a": (5.0, 6.0, 7.0),
    "pkg/short_b": (3.0, 3.5, 4.0),
    "other/tiny": (0.2, 0.3, 0.25),
}


@pytest.fixture
def history(tmp_path: Path) -> Path:
    """A test history of three runs of :data:`RUNS`."""
    db = tmp_path / "history.sqlite3"
    for k in range(3):
        tree = tmp_path / f"run{k}"
        for name, seconds in RUNS.items():
            runner_file(tree, name, seconds[k], started=START + 1000 * k)
        assert record.record(db, [tree]) is True
    return db


@pytest.fixture
def written(history: Path, env: dict[str, str]) -> Path:
    """The durations file ``history durations`` writes from :func:`history`."""
    path = history.parent / "durations.json"
    proc = run_cli(["history", "durations", "--db", str(history), str(path)], env)
    assert proc.returncode == 0, proc.stderr
    return path


def test_the_database_reads_as_the_file_history_durations_writes(
    history: Path, written: Path
) -> None:
    from_db, from_file = load(history), load(written)
    assert from_db == from_file and from_db.fingerprint == from_file.fingerprint
    assert from_db.micros["pkg/long"] == 100_000_000  # the median of 90, 100 and 400
    assert HISTORY_APPLICATION_ID == store.APPLICATION_ID


def test_shard_plan_from_the_database_and_from_the_file_is_the_same(
    history: Path, written: Path, env: dict[str, str]
) -> None:
    def plan(source: Path, *extra: str) -> str:
        argv = ["shard", "--plan", "--total", "2", "--durations", str(source), *extra]
        proc = run_cli(argv, env)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr
        return proc.stdout.replace(str(source), "SOURCE")

    assert plan(history) == plan(written)
    assert plan(history, "--json") == plan(written, "--json")
    assert "pkg/long" in plan(history)
    # The variable names the database as the option does.
    proc = run_cli(["shard", "--plan", "--total", "2"], {**env, DURATIONS_ENV: str(history)})
    assert proc.stdout.replace(str(history), "SOURCE") == plan(written)
    # Control: by count (no durations) the plan is another one.
    by_count = run_cli(["shard", "--plan", "--total", "2", str(history.parent / "run0")], env)
    assert by_count.returncode == 0 and "by count" in by_count.stdout.lower()


def test_the_runner_plans_from_the_database_as_from_the_file(
    history: Path, written: Path, env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    selection = Selection(Share(1, 2), load(written))
    here = [name for name in RUNS if selection.runs(*name.split("/"))]
    elsewhere = [name for name in RUNS if name not in here]
    assert here and elsewhere
    for name in (here[0], elsewhere[0]):
        package, test = name.split("/")
        result = tmp_path / "results" / package / f"{test}.xml"
        marker = tmp_path / f"ran-{test}"
        proc = ament(
            runner_script, result, ["touch", str(marker)],
            {**env, SHARD_ENV: "1/2", DURATIONS_ENV: str(history)},
            "--generate-result-on-success", cwd=tmp_path, package=package,
        )  # fmt: skip
        if name in here:
            assert proc.returncode == 0, proc.stdout + proc.stderr
            assert marker.exists()
            plan = load_result(result).properties["shard_plan"]
            assert plan == load(written).fingerprint
        else:
            assert proc.returncode == 77, proc.stdout + proc.stderr
            assert not marker.exists()
            assert f"plan {load(written).fingerprint}" in proc.stdout


def test_a_foreign_sqlite_file_is_refused_in_one_line(tmp_path: Path, env: dict[str, str]) -> None:
    foreign = tmp_path / "other.sqlite3"
    with sqlite3.connect(foreign) as other:
        other.execute("CREATE TABLE runs (x)")
    other.close()
    with pytest.raises(DurationsError, match="an SQLite file of another program"):
        load(foreign)
    proc = run_cli(["shard", "--plan", "--total", "2", "--durations", str(foreign)], env)
    assert proc.returncode == 2
    assert "not a test history" in the_error_line(proc)
    # Control: a history database (even of no runs yet) is read.
    empty = tmp_path / "empty.sqlite3"
    store.connect(empty).close()
    assert len(load(empty)) == 0
