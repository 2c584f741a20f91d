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
