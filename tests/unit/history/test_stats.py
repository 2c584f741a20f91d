"""A test's status over the window: new, stable, broken (since when), flaky, skipped."""

from __future__ import annotations

from pathlib import Path

from helpers.split_trees import START, runner_file

from ros_isolated_test.history import record, stats, store


def _runs(tmp_path: Path, outcomes: str) -> list[stats.TestStats]:
    """One run per character of ``outcomes`` (P passed, F failed) of the test pkg/t."""
    db = tmp_path / "h.sqlite3"
    for number, outcome in enumerate(outcomes):
        tree = tmp_path / f"run{number}"
        path = runner_file(tree, "pkg/t", 1.0 + number, started=START + 100 * number)
        if outcome == "F":
            case = f'time="{1.0 + number:.3f}"'
            failed = f'{case}><failure message="no">no</failure></testcase>'
            path.write_text(path.read_text().replace(f"{case}/>", failed))
        record.record(db, [tree])
    connection = store.connect(db, write=False)
    try:
        return stats.tests(connection, runs=3)
    finally:
        connection.close()


def test_the_status_of_each_history(tmp_path: Path) -> None:
    cases = {"P": "new", "PPP": "stable", "PFFF": "broken", "PFF": "flaky", "FFPPP": "stable"}
    for k, (outcomes, status) in enumerate(cases.items()):
        (item,) = _runs(tmp_path / str(k), outcomes)
        assert item.status == status, outcomes
        assert item.strip == outcomes[-3:]


def test_broken_since_the_first_failure_of_the_streak(tmp_path: Path) -> None:
    (item,) = _runs(tmp_path, "PPFFF")
    since = item.broken_since
    assert since is not None and since.number == 3
    assert item.as_json()["median_seconds"] == 4.0


def test_before_run_judges_a_run_by_the_runs_before_it(tmp_path: Path) -> None:
    """A failure after passes is new, whether or not its own run is recorded yet."""
    _runs(tmp_path, "PPF")  # recorded runs 0-2 of pkg/t; run2 failed
    db = tmp_path / "h.sqlite3"
    (now,) = [path for path in (tmp_path / "run2").rglob("*.xml")]
    past = stats.before_run(db, [tmp_path / "run2"])["pkg/t"]
    assert (past.kind, past.strip, past.runs, past.failing) == ("new", "PP", 2, 0)
    # Control: the whole window, the failing run in it, calls it flaky.
    connection = store.connect(db, write=False)
    (item,) = stats.tests(connection)
    connection.close()
    assert item.status == "flaky" and now.is_file()
    # Failed in every run before: broken since the first of them; a pass among them: flaky.
    for k, (outcomes, kind, since) in enumerate(
        (("FFFF", "broken", "run 1"), ("PFFF", "flaky", ""))
    ):
        _runs(tmp_path / str(k), outcomes)
        run = tmp_path / str(k) / "run3"
        past = stats.before_run(tmp_path / str(k) / "h.sqlite3", [run])["pkg/t"]
        assert (past.kind, past.strip, past.since[:5]) == (kind, outcomes[:3], since)
    assert stats.before_run(tmp_path / "absent.sqlite3", [tmp_path / "run2"]) == {}
