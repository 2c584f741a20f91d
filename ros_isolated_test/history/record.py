"""The result trees of one run into the history: every attempt of every test, once.

A test is named as the split names it (``report.shard_durations``): a runner's file is one
test, ``<package>/<test>``; pytest's own file under the plugin one test per item. Its
attempts come from the file: a rerun test's earlier attempts each failed (a test is run
again only after failing) and keep their own exit, domain ID and duration
(``attempt_<k>.*``); the last attempt has the file's outcome. A file that names no such
test (another producer's file) is not recorded.

A run's identity is the SHA-256 of its tests' identities and start times, so recording
the same results again, or a copy of them on another machine, finds the same run and
changes nothing; every write is one transaction. :func:`record_trees` is the one entry
for other code (``run``, the pytest plugin, colcon's event handler): it never raises,
it returns the one warning line to print.
"""

from __future__ import annotations

import hashlib
import os
import socket
import sqlite3
from datetime import datetime, timezone
from pathlib import Path

from ros_isolated_test import __version__, names
from ros_isolated_test.history.store import StoreError, connect, problem, prune, stored
from ros_isolated_test.report.shard_durations import named_tests
from ros_isolated_test.report.tree import FileRead, read_tree
from ros_isolated_test.shard.identity import IdentityError, split

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Iterable

#: The outcomes an attempt may have; ``FAILING`` are those that fail a run.
OUTCOMES = ("passed", "failed", "error", "skipped", "timed out", "not run")
FAILING = frozenset(("failed", "error", "timed out"))
#: Characters of a failure's first line kept as its signature.
SIGNATURE_LIMIT = 200
#: Where CI services say the commit, branch and job (GitHub Actions, GitLab, Jenkins).
_COMMIT = ("GITHUB_SHA", "CI_COMMIT_SHA", "GIT_COMMIT")
_BRANCH = ("GITHUB_REF_NAME", "CI_COMMIT_REF_NAME", "GIT_BRANCH")
_JOB = ("CI_JOB_URL", "BUILD_URL")

#: One attempt: outcome, seconds (None: not measured), domain ID, failure signature.
AttemptRow = tuple[str, float | None, int | None, str]


class Run:
    """What one run's trees hold: its tests' attempts, and where and when it ran."""

    def __init__(self) -> None:
        self.tests: dict[str, list[AttemptRow]] = {}
        self.starts: dict[str, str] = {}
        self.host = ""
        self.shard = ""
        self.plan = ""
        self.version = ""

    @property
    def key(self) -> str:
        """The run's identity: its tests and their start times, hashed."""
        digest = hashlib.sha256()
        for name in sorted(self.tests):
            digest.update(name.encode("utf-8", "surrogatepass") + b"\0")
            digest.update(self.starts.get(name, "").encode() + b"\n")
        return digest.hexdigest()

    @property
    def started(self) -> str:
        """When its first test started (ISO 8601), else now."""
        found = [start for start in self.starts.values() if start]
        return min(found) if found else datetime.now(timezone.utc).isoformat()

    def add(self, item: FileRead) -> None:
        """The tests of one result file."""
        read = item.read
        if read is None or not read.suites:
            return
        properties = read.suites[0].properties
        self.host = self.host or read.suites[0].attrs.get("hostname", "")
        self.shard = self.shard or properties.get(names.SHARD_PROPERTY, "")
        self.plan = self.plan or properties.get(names.SHARD_PLAN, "")
        self.version = self.version or properties.get(names.RUNNER_VERSION, "")
        if len(read.suites) == 1 and names.RUNNER_VERSION in properties:
            for name, seconds in named_tests(item):
                self.tests[name] = _runner_attempts(item, seconds)
                self.starts[name] = properties.get(
                    "attempt_1.started_at",
                    properties.get(names.STARTED_AT, read.suites[0].attrs.get("timestamp", "")),
                )
            return
        self._items(item)

    def _items(self, item: FileRead) -> None:
        """Pytest's own file: each item named by its identity property, once."""
        assert item.read is not None
        seconds_of = dict(named_tests(item))
        domain = _domain(item.read.suites[0].properties.get(names.DOMAIN_ID, ""))
        for case in item.read.cases:
            try:
                split(case.identity)
            except IdentityError:
                continue
            tags = [outcome.tag for outcome in case.outcomes]
            earlier = [tag for tag in tags if tag.startswith(("flaky", "rerun"))]
            final = "passed"
            for tag, said in (("skipped", "skipped"), ("failure", "failed"), ("error", "error")):
                if tag in tags:
                    final = said
            signature = next(
                (
                    _signature(o.attrs.get("message", "") or o.text)
                    for o in case.outcomes
                    if not o.tag.startswith("skip")
                ),
                "",
            )
            rows: list[AttemptRow] = [("failed", None, domain, signature) for _ in earlier]
            rows.append(
                (
                    final,
                    seconds_of.get(case.identity),
                    domain,
                    signature if final in FAILING else "",
                )
            )
            self.tests[case.identity] = rows
            self.starts[case.identity] = item.read.suites[case_suite(item, case.suite)].attrs.get(
                "timestamp", ""
            )


def case_suite(item: FileRead, name: str) -> int:
    """The index of the suite called ``name`` in the file (the first when none is)."""
    assert item.read is not None
    return next((k for k, suite in enumerate(item.read.suites) if suite.name == name), 0)


def _domain(text: str) -> int | None:
    return int(text) if text.isdigit() else None


def _seconds(text: str | None) -> float | None:
    try:
        return float(text) if text else None
    except ValueError:
        return None


def _signature(text: str) -> str:
    """A failure's first non-empty line, bounded: what tells one failure from another."""
    line = next((line.strip() for line in text.splitlines() if line.strip()), "")
    return line[:SIGNATURE_LIMIT]


def _final(item: FileRead) -> str:
    """The last attempt's outcome of a runner's file."""
    assert item.read is not None
    exit_text = item.read.suites[0].properties.get(names.EXIT, "")
    report = item.report
    if exit_text == "not run":
        return "not run"
    if "timed out" in exit_text:
        return "timed out"
    if report.errors:
        return "error"
    if report.failures:
        return "failed"
    if report.tests and report.skipped == report.tests:
        return "skipped"
    return "passed"


def _runner_attempts(item: FileRead, seconds: float | None) -> list[AttemptRow]:
    """Every attempt of a runner's test: the earlier ones failed, the last as the file says."""
    assert item.read is not None
    properties = item.read.suites[0].properties
    total = int(properties.get(names.ATTEMPTS, "1") or 1)
    rows: list[AttemptRow] = []
    for number in range(1, total):
        exit_text = properties.get(f"attempt_{number}.exit", properties.get(names.EXIT, ""))
        rows.append(
            (
                "timed out" if "timed out" in exit_text else "failed",
                _seconds(
                    properties.get(f"attempt_{number}.duration", properties.get(names.DURATION))
                ),
                _domain(
                    properties.get(
                        f"attempt_{number}.ros_domain_id", properties.get(names.DOMAIN_ID, "")
                    )
                ),
                _signature(exit_text),
            )
        )
    final = _final(item)
    signature = ""
    if final in FAILING:
        failed = next((case for case in item.cases if case.outcome.failed), None)
        signature = _signature(failed.message if failed else properties.get(names.EXIT, ""))
    rows.append((final, seconds, _domain(properties.get(names.DOMAIN_ID, "")), signature))
    return rows


def gathered(trees: Iterable[Path]) -> Run:
    """The run the result trees (files or folders) hold."""
    run = Run()
    for item in read_tree(trees):
        run.add(item)
    return run


def _first(names: tuple[str, ...]) -> str:
    return next((os.environ[name] for name in names if os.environ.get(name)), "")


def _job_url() -> str:
    if os.environ.get("GITHUB_RUN_ID") and os.environ.get("GITHUB_REPOSITORY"):
        server = os.environ.get("GITHUB_SERVER_URL", "")
        return (
            f"{server}/{os.environ['GITHUB_REPOSITORY']}/actions/runs/{os.environ['GITHUB_RUN_ID']}"
        )
    return _first(_JOB)


def write(connection: sqlite3.Connection, run: Run) -> bool:
    """``run`` into the database, in one transaction; whether anything was new.

    A run already there (the same key) gains only attempts it lacked: none, when the
    same results are recorded again. The oldest runs beyond the kept number go.
    """
    if not run.tests:
        return False
    connection.execute("BEGIN IMMEDIATE")
    try:
        before = connection.total_changes
        connection.execute(
            "INSERT OR IGNORE INTO runs (key, started, host, git_commit, branch, job_url, distro,"
            " rmw, shard, plan, tool_version, recorded) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
            (
                run.key,
                run.started,
                run.host or socket.gethostname(),
                _first(_COMMIT),
                _first(_BRANCH),
                _job_url(),
                os.environ.get("ROS_DISTRO", ""),
                os.environ.get("RMW_IMPLEMENTATION", ""),
                run.shard,
                run.plan,
                run.version or __version__,
                datetime.now(timezone.utc).isoformat(),
            ),
        )
        run_id = connection.execute("SELECT id FROM runs WHERE key = ?", (run.key,)).fetchone()[0]
        names = [stored(name) for name in run.tests]
        connection.executemany(
            "INSERT OR IGNORE INTO tests (name) VALUES (?)", ((n,) for n in names)
        )
        ids = _test_ids(connection, names)
        connection.executemany(
            "INSERT OR IGNORE INTO attempts VALUES (?,?,?,?,?,?,?)",
            (
                (run_id, ids[stored(name)], number, *row)
                for name, rows in run.tests.items()
                for number, row in enumerate(rows, start=1)
            ),
        )
        changed = connection.total_changes != before
        if changed:
            prune(connection)
        connection.execute("COMMIT")
    except BaseException:
        connection.execute("ROLLBACK")
        raise
    return changed


def _test_ids(connection: sqlite3.Connection, names: list[str | bytes]) -> dict[str | bytes, int]:
    """The ids of the tests ``names``, in chunks SQLite's parameter limit allows."""
    ids: dict[str | bytes, int] = {}
    for start in range(0, len(names), 500):
        chunk = names[start : start + 500]
        marks = ",".join("?" * len(chunk))
        ids.update(connection.execute(f"SELECT name, id FROM tests WHERE name IN ({marks})", chunk))
    return ids


def record(db: Path, trees: Iterable[Path] | Run) -> bool:
    """The run in ``trees`` (or one read already) into ``db``; whether it was new.

    Raises :class:`StoreError` for a database that cannot be used.
    """
    run = trees if isinstance(trees, Run) else gathered(trees)
    connection = connect(db)
    try:
        return write(connection, run)
    except sqlite3.Error as error:
        raise problem(db, error) from None
    finally:
        connection.close()


def record_trees(db: Path, trees: Iterable[Path] | Run) -> str | None:
    """Record, never raising: None when done, else the one warning line to print.

    For code that records as a side effect (``run``, the pytest plugin, colcon's event
    handler): a locked, corrupt, foreign or unwritable database must not change a test's
    result or exit code.
    """
    try:
        record(db, trees)
    except StoreError as error:
        return f"ros-isolated-test: warning: not recorded in the {error}"
    except Exception as error:
        return f"ros-isolated-test: warning: not recorded in the {problem(db, error)}"
    return None
