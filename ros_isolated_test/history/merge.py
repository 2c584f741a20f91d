"""Databases of several machines (a split's shares, parallel jobs) joined into one.

Runs are matched by their identity and tests by their name, so merging the same
database twice, or one that shares runs with the target, adds only what was missing.
Each source is checked as ours first and read, never written.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

from ros_isolated_test.history.store import StoreError, connect, problem, prune

_COLUMNS = (
    "key, started, host, git_commit, branch, job_url, distro, rmw, shard, plan, tool_version,"
    " recorded"
)


def merge(target: Path, sources: list[Path]) -> int:
    """Every run of ``sources`` into ``target`` (created if absent); how many runs were new."""
    for source in sources:
        connect(source, write=False).close()  # ours, at this schema: else StoreError
    connection = connect(target)
    try:
        before = connection.execute("SELECT count(*) FROM runs").fetchone()[0]
        for source in sources:
            _merged(connection, source)
        prune(connection)
        return int(connection.execute("SELECT count(*) FROM runs").fetchone()[0]) - int(before)
    except sqlite3.Error as error:
        raise problem(target, error) from None
    finally:
        connection.close()


def _merged(connection: sqlite3.Connection, source: Path) -> None:
    """One source's runs, tests and attempts, in one transaction."""
    uri = f"{source.absolute().as_uri()}?mode=ro"
    try:
        connection.execute("ATTACH DATABASE ? AS source", (uri,))
    except sqlite3.Error as error:
        raise problem(source, error) from None
    try:
        connection.execute("BEGIN IMMEDIATE")
        try:
            connection.execute(
                f"INSERT OR IGNORE INTO runs ({_COLUMNS}) SELECT {_COLUMNS} FROM source.runs"
            )
            connection.execute("INSERT OR IGNORE INTO tests (name) SELECT name FROM source.tests")
            connection.execute(
                "INSERT OR IGNORE INTO attempts SELECT r.id, t.id, a.attempt, a.outcome,"
                " a.seconds, a.domain_id, a.signature FROM source.attempts a"
                " JOIN source.runs sr ON sr.id = a.run JOIN main.runs r ON r.key = sr.key"
                " JOIN source.tests st ON st.id = a.test JOIN main.tests t ON t.name = st.name"
            )
            connection.execute("COMMIT")
        except BaseException:
            connection.execute("ROLLBACK")
            raise
    except sqlite3.Error as error:
        raise problem(source, error) from None
    finally:
        connection.execute("DETACH DATABASE source")


__all__ = ["StoreError", "merge"]
