"""Each test over the last runs of the history: how it went, and whether it is to be trusted.

The window is the last ``N`` runs of the database, newest by start. Per test, over the
runs of the window it was in: how many it passed and failed by its last attempt, how
many it passed only after failing (flaky within a run), the median and slowest last
attempt, and its outcomes as a strip, oldest first. Its status:

- ``new``: in one run only;
- ``flaky``: passes and failures in the window, or passed after failing within a run;
- ``broken``: failed in every run of the window it ran in (at least 2), with the first
  run of that unbroken streak;
- ``stable``: passed in every run it ran in;
- ``skipped``: never ran to a pass or a failure (skipped, or not run).

"Not run" and "skipped" count neither as a pass nor as a failure.
"""

from __future__ import annotations

import sqlite3
import statistics
from dataclasses import dataclass, field

from ros_isolated_test.history.record import FAILING, Run, gathered
from ros_isolated_test.history.store import connect, loaded, stored
from ros_isolated_test.report.html_parts import Past

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Iterable
    from pathlib import Path

#: Runs a window holds unless ``--runs`` says otherwise.
DEFAULT_RUNS = 20
#: Worst first: the order ``history`` lists tests in.
STATUSES = ("broken", "flaky", "new", "skipped", "stable")
#: One character per run in a strip: the last attempt's outcome, ``f`` passed after failing.
STRIP = {
    "passed": "P",
    "flaky": "f",
    "failed": "F",
    "error": "E",
    "timed out": "T",
    "skipped": "S",
    "not run": "N",
}


@dataclass
class RunInfo:
    """A run of the window: its number (1 = the oldest kept), start and commit."""

    number: int
    key: str
    started: str
    commit: str

    def as_json(self) -> dict[str, object]:
        return {"run": self.number, "key": self.key, "started": self.started, "commit": self.commit}


@dataclass
class TestStats:
    """One test over the window."""

    test: str
    #: The last outcome of each run it was in, oldest first (``flaky``: passed after failing).
    outcomes: list[str] = field(default_factory=list)
    runs_in: list[RunInfo] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    #: Runs in which any attempt failed (a flaky pass included).
    failing_runs: int = 0
    signature: str = ""

    @property
    def runs(self) -> int:
        return len(self.outcomes)

    @property
    def passed(self) -> int:
        return sum(1 for outcome in self.outcomes if outcome in ("passed", "flaky"))

    @property
    def failed(self) -> int:
        return sum(1 for outcome in self.outcomes if outcome in FAILING)

    @property
    def flaky(self) -> int:
        return self.outcomes.count("flaky")

    @property
    def status(self) -> str:
        if self.runs == 1:
            return "new"
        if self.flaky or (self.passed and self.failed):
            return "flaky"
        if self.failed >= 2 and not self.passed:
            return "broken"
        return "stable" if self.passed else ("broken" if self.failed else "skipped")

    @property
    def broken_since(self) -> RunInfo | None:
        """The first run of the unbroken streak of failures that ends the window."""
        if self.status != "broken":
            return None
        return self.failing_since

    @property
    def failing_since(self) -> RunInfo | None:
        """The first run of the streak of failures that ends the window, if it ends so."""
        since = None
        for outcome, run in zip(reversed(self.outcomes), reversed(self.runs_in), strict=True):
            if outcome in FAILING:
                since = run
            elif outcome in ("passed", "flaky"):
                break
        return since

    @property
    def strip(self) -> str:
        return "".join(STRIP[outcome] for outcome in self.outcomes)

    def as_json(self) -> dict[str, object]:
        since = self.broken_since
        return {
            "test": self.test,
            "status": self.status,
            "runs": self.runs,
            "passed": self.passed,
            "failed": self.failed,
            "flaky": self.flaky,
            "failing_runs": self.failing_runs,
            "median_seconds": statistics.median(self.seconds) if self.seconds else None,
            "slowest_seconds": max(self.seconds) if self.seconds else None,
            "strip": self.strip,
            "broken_since": since.as_json() if since else None,
            "last_failure": self.signature,
        }


def window(connection: sqlite3.Connection, runs: int = DEFAULT_RUNS) -> list[RunInfo]:
    """The last ``runs`` runs, oldest first, numbered from the oldest kept run."""
    return [info for _, info in _window(connection, runs)]


def _window(
    connection: sqlite3.Connection, runs: int, leave_out: str = ""
) -> list[tuple[int, RunInfo]]:
    """The window's runs by their row id, oldest first (without the run ``leave_out``)."""
    total = connection.execute("SELECT count(*) FROM runs").fetchone()[0]
    rows = connection.execute(
        "SELECT id, key, started, git_commit FROM runs ORDER BY started DESC, id DESC",
    )
    found: list[tuple[int, RunInfo]] = []
    for k, (run, key, started, commit) in enumerate(rows):
        if len(found) == runs:
            break
        if key != leave_out:
            found.append((run, RunInfo(total - k, key, started, commit)))
    return found[::-1]


def tests(
    connection: sqlite3.Connection,
    runs: int = DEFAULT_RUNS,
    names: list[str] | None = None,
    leave_out: str = "",
) -> list[TestStats]:
    """Every test of the window (or only ``names``), worst first.

    ``leave_out``: the key of a run not to count (the run a page is drawn for: what
    came before it says whether its failures are new).
    """
    info_of = dict(_window(connection, runs, leave_out))
    found: dict[int, TestStats] = {}
    query = (
        "SELECT a.test, a.run, a.outcome, a.seconds, a.signature FROM attempts a"
        " WHERE a.run IN (SELECT id FROM runs WHERE key != ?"
        " ORDER BY started DESC, id DESC LIMIT ?)"
    )
    parameters: list[object] = [leave_out, runs]
    if names is not None:
        wanted = [stored(name) for name in names]
        query += (
            f" AND a.test IN (SELECT id FROM tests WHERE name IN ({','.join('?' * len(wanted))}))"
        )
        parameters += wanted
    query += " ORDER BY a.test, a.run, a.attempt"
    # Rows come test by test: each test's runs are folded as soon as the next test
    # starts, so memory holds one test's attempts, not the window's.
    current: int | None = None
    last: dict[int, tuple[str, float | None, bool, str]] = {}
    for test, run, outcome, seconds, signature in connection.execute(query, parameters):
        if test != current:
            if current is not None:
                found[current] = _folded(last, info_of)
            current, last = test, {}
        before = last.get(run)
        failed_before = before is not None and (before[2] or before[0] in FAILING)
        last[run] = (outcome, seconds, failed_before, signature or (before[3] if before else ""))
    if current is not None:
        found[current] = _folded(last, info_of)
    names_of = _names(connection, list(found))
    for test, stats in found.items():
        stats.test = names_of[test]
    return sorted(found.values(), key=_worst_first)


def _folded(
    last: dict[int, tuple[str, float | None, bool, str]], info_of: dict[int, RunInfo]
) -> TestStats:
    """One test's runs (run -> its last attempt, whether one failed before it) folded."""
    stats = TestStats("")
    for run in sorted(last, key=lambda run: info_of[run].number):
        outcome, seconds, failed_before, signature = last[run]
        flaky = outcome == "passed" and failed_before
        stats.outcomes.append("flaky" if flaky else outcome)
        stats.runs_in.append(info_of[run])
        if seconds is not None:
            stats.seconds.append(seconds)
        if failed_before or outcome in FAILING:
            stats.failing_runs += 1
            stats.signature = signature or stats.signature
    return stats


def before_run(db: Path, trees: Iterable[Path] | Run, runs: int = DEFAULT_RUNS) -> dict[str, Past]:
    """What the runs before the run in ``trees`` (or one read already) say of each test.

    For the report's page. The run itself is left out where it is recorded already, so
    a failure is judged by what came before it: ``new`` (it never failed before, or was
    never seen), ``broken`` (it failed in every run before it ran in, since the first of
    them) or ``flaky``.
    A database that does not exist yet is an empty history; one that cannot be read
    raises :class:`~ros_isolated_test.history.store.StoreError`.
    """
    if not db.exists():
        return {}
    leave_out = (trees if isinstance(trees, Run) else gathered(trees)).key
    connection = connect(db, write=False)
    try:
        found = tests(connection, runs, leave_out=leave_out)
    finally:
        connection.close()
    pasts: dict[str, Past] = {}
    for item in found:
        kind, since = "flaky", ""
        if not item.failing_runs:
            kind = "new"
        elif not item.passed:
            kind = "broken"
            first = item.failing_since
            if first is not None:
                since = f"run {first.number} ({first.started[:16].replace('T', ' ')})"
        pasts[item.test] = Past(kind, item.strip, item.runs, item.failing_runs, since)
    return pasts


def status_of(connection: sqlite3.Connection, name: str, runs: int = DEFAULT_RUNS) -> str | None:
    """The status of test ``name`` over the last ``runs`` runs it was in; None: never seen.

    The test's own last runs, not the database's: a RUNNER records each test as a run of
    its own, so the database's last runs may hold none of this test's.
    """
    rows = connection.execute(
        "SELECT a.run, a.outcome FROM attempts a WHERE a.test = (SELECT id FROM tests"
        " WHERE name = ?) AND a.run IN (SELECT b.run FROM attempts b JOIN runs r"
        " ON r.id = b.run WHERE b.test = (SELECT id FROM tests WHERE name = ?)"
        " AND b.attempt = 1 ORDER BY r.started DESC, r.id DESC LIMIT ?)"
        " ORDER BY a.run, a.attempt",
        (stored(name), stored(name), runs),
    )
    last: dict[int, tuple[str, bool]] = {}
    for run, outcome in rows:
        before = last.get(run)
        last[run] = (outcome, before is not None and (before[1] or before[0] in FAILING))
    if not last:
        return None
    stats = TestStats(name)
    for outcome, failed_before in last.values():
        stats.outcomes.append("flaky" if outcome == "passed" and failed_before else outcome)
    return stats.status


def called_flaky(db: Path, name: str, runs: int = DEFAULT_RUNS) -> bool:
    """Whether the history at ``db`` calls test ``name`` flaky over its last runs.

    False for a database that is not there or cannot be read: deciding on a rerun
    never fails a test.
    """
    if not db.exists():
        return False
    try:
        connection = connect(db, write=False)
    except Exception:
        return False
    try:
        return status_of(connection, name, runs) == "flaky"
    except sqlite3.Error:
        return False
    finally:
        connection.close()


def _worst_first(stats: TestStats) -> tuple[int, int, str]:
    return (STATUSES.index(stats.status), -stats.failing_runs, stats.test)


def _names(connection: sqlite3.Connection, ids: list[int]) -> dict[int, str]:
    names: dict[int, str] = {}
    for start in range(0, len(ids), 500):
        chunk = ids[start : start + 500]
        marks = ",".join("?" * len(chunk))
        for test, name in connection.execute(
            f"SELECT id, name FROM tests WHERE id IN ({marks})", chunk
        ):
            names[test] = loaded(name)
    return names
