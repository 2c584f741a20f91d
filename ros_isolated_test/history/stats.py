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

from ros_isolated_test.history.record import FAILING
from ros_isolated_test.history.store import loaded, stored

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


def _window(connection: sqlite3.Connection, runs: int) -> list[tuple[int, RunInfo]]:
    """The window's runs by their row id, oldest first."""
    total = connection.execute("SELECT count(*) FROM runs").fetchone()[0]
    rows = connection.execute(
        "SELECT id, key, started, git_commit FROM runs ORDER BY started DESC, id DESC LIMIT ?",
        (runs,),
    ).fetchall()
    found = [
        (run, RunInfo(total - k, key, started, commit))
        for k, (run, key, started, commit) in enumerate(rows)
    ]
    return found[::-1]


def tests(
    connection: sqlite3.Connection, runs: int = DEFAULT_RUNS, names: list[str] | None = None
) -> list[TestStats]:
    """Every test of the window (or only ``names``), worst first."""
    info_of = dict(_window(connection, runs))
    found: dict[int, TestStats] = {}
    last: dict[tuple[int, int], tuple[str, float | None, bool, str]] = {}
    query = (
        "SELECT a.test, a.run, a.outcome, a.seconds, a.signature FROM attempts a"
        " WHERE a.run IN (SELECT id FROM runs ORDER BY started DESC, id DESC LIMIT ?)"
    )
    parameters: list[object] = [runs]
    if names is not None:
        wanted = [stored(name) for name in names]
        query += (
            f" AND a.test IN (SELECT id FROM tests WHERE name IN ({','.join('?' * len(wanted))}))"
        )
        parameters += wanted
    query += " ORDER BY a.test, a.run, a.attempt"
    for test, run, outcome, seconds, signature in connection.execute(query, parameters):
        key = (test, run)
        before = last.get(key)
        failed_before = before is not None and (before[2] or before[0] in FAILING)
        last[key] = (outcome, seconds, failed_before, signature or (before[3] if before else ""))
    per_test: dict[int, list[tuple[int, tuple[str, float | None, bool, str]]]] = {}
    for (test, run), value in last.items():
        per_test.setdefault(test, []).append((run, value))
    names_of = _names(connection, list(per_test))
    for test, seen in per_test.items():
        stats = TestStats(names_of[test])
        seen.sort(key=lambda item: info_of[item[0]].number)
        for run, (outcome, seconds, failed_before, signature) in seen:
            flaky = outcome == "passed" and failed_before
            stats.outcomes.append("flaky" if flaky else outcome)
            stats.runs_in.append(info_of[run])
            if seconds is not None:
                stats.seconds.append(seconds)
            if failed_before or outcome in FAILING:
                stats.failing_runs += 1
                stats.signature = signature or stats.signature
        found[test] = stats
    return sorted(found.values(), key=_worst_first)


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
