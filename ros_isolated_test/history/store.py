"""The history database: its schema, how it is opened, migrated and kept bounded.

Python's own ``sqlite3``, one file. WAL mode and a busy timeout so that many recorders
(the machines' runners, eight ``history record`` at once) and readers share it without
errors; each write is one ``BEGIN IMMEDIATE`` transaction, so a recorder killed midway
leaves the database as it was. ``PRAGMA application_id`` marks the file as ours: a
foreign SQLite file is refused, never changed. ``PRAGMA user_version`` is the schema
version; :data:`MIGRATIONS` takes any older database up to the current one in order.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

#: The database's name where no option or variable names one: in the current folder for
#: ``history`` and reruns, in the workspace for the colcon extension (its folder).
DEFAULT_FILE = "ros_isolated_test_history.sqlite3"
#: ``PRAGMA application_id`` of a history database ("RITH").
APPLICATION_ID = 0x52495448
#: Runs kept unless ``history prune --keep`` said otherwise.
DEFAULT_KEEP = 200
#: How long a writer waits for another's transaction to end, in milliseconds.
BUSY_TIMEOUT_MS = 60_000
#: The fix a warning about a database gives.
FIX = "delete or move the file to start a new history, or name another with --db"

#: Each step takes the schema from version k to k+1 (``MIGRATIONS[k]``).
MIGRATIONS: tuple[str, ...] = (
    # 1: runs, tests and every attempt of every test of every run.
    """
    CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
    CREATE TABLE runs (
        id INTEGER PRIMARY KEY,
        key TEXT NOT NULL UNIQUE,
        started TEXT NOT NULL,
        host TEXT NOT NULL DEFAULT '',
        git_commit TEXT NOT NULL DEFAULT '',
        branch TEXT NOT NULL DEFAULT '',
        job_url TEXT NOT NULL DEFAULT '',
        distro TEXT NOT NULL DEFAULT '',
        rmw TEXT NOT NULL DEFAULT '',
        shard TEXT NOT NULL DEFAULT '',
        plan TEXT NOT NULL DEFAULT '',
        tool_version TEXT NOT NULL DEFAULT ''
    );
    CREATE TABLE tests (id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE);
    CREATE TABLE attempts (
        run INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,
        test INTEGER NOT NULL REFERENCES tests(id),
        attempt INTEGER NOT NULL,
        outcome TEXT NOT NULL,
        seconds REAL,
        domain_id INTEGER,
        signature TEXT NOT NULL DEFAULT '',
        PRIMARY KEY (run, test, attempt)
    ) WITHOUT ROWID;
    """,
    # 2: runs read newest first by start; the recording time kept apart from the start.
    """
    CREATE INDEX runs_by_start ON runs (started, id);
    ALTER TABLE runs ADD COLUMN recorded TEXT NOT NULL DEFAULT '';
    """,
)
VERSION = len(MIGRATIONS)


class StoreError(Exception):
    """A database that cannot be used: locked, corrupt, foreign, newer or unwritable.

    Its text is one line naming the file and the fix.
    """


#: The fix when there is no database yet: nothing to delete, a run to record.
FIX_MISSING = (
    "record a run first (ros-isolated-test history record, or colcon test with the "
    "colcon extension), or name another with --db"
)


def problem(path: Path, error: BaseException, fix: str = FIX) -> StoreError:
    """``error`` met on the database at ``path`` as one line naming the file and the fix."""
    from ros_isolated_test.text import display_text

    said = " ".join(str(error).split()) or type(error).__name__
    return StoreError(f"history database {display_text(str(path))}: {said}; {fix}")


def connect(path: Path, write: bool = True) -> sqlite3.Connection:
    """The database at ``path``, at the current schema; created when ``write`` and absent.

    Raises :class:`StoreError` for any database that cannot be used as it is.
    """
    if not write and not path.exists():
        raise problem(path, FileNotFoundError("no such file"), FIX_MISSING)
    try:
        if write:
            connection = sqlite3.connect(path, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
        else:
            uri = f"{path.absolute().as_uri()}?mode=ro"
            connection = sqlite3.connect(
                uri, uri=True, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None
            )
    except (sqlite3.Error, OSError) as error:
        raise problem(path, error) from None
    try:
        connection.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        connection.execute("PRAGMA foreign_keys = ON")
        _shaped(connection, path, write)
    except StoreError:
        connection.close()
        raise
    except sqlite3.Error as error:
        connection.close()
        raise problem(path, error) from None
    return connection


def _shaped(connection: sqlite3.Connection, path: Path, write: bool) -> None:
    """Check the file is ours and at the current schema, migrating (or creating) it."""
    version = _checked(connection, path)
    if version != VERSION:
        if not write:
            raise problem(
                path, ValueError(f"schema version {version}, not {VERSION}: record into it")
            )
        _migrated(connection, path)
    if write:
        _in_wal_mode(connection)


def _migrated(connection: sqlite3.Connection, path: Path) -> None:
    """Take the database to the current schema in one transaction (creating it if empty)."""
    connection.execute("BEGIN IMMEDIATE")
    try:
        version = _checked(connection, path)  # another process may have done it meanwhile
        for step in MIGRATIONS[version:]:
            for statement in step.split(";"):
                if statement.strip():
                    connection.execute(statement)
        connection.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        connection.execute(f"PRAGMA user_version = {VERSION}")
        connection.execute("COMMIT")
    except BaseException:
        connection.execute("ROLLBACK")
        raise


def _in_wal_mode(connection: sqlite3.Connection) -> None:
    """Put the file in WAL mode (kept by the file) unless another process is using it.

    WAL lets readers and a writer share the file. Switching needs the file alone for a
    moment and SQLite does not wait for that (the busy timeout is not used): when
    eight recorders create one database at once, all but one were refused with
    "database is locked". A busy switch is left to the next writer; until then the
    file works in rollback mode, where the busy timeout serialises everyone.
    """
    if connection.execute("PRAGMA journal_mode").fetchone()[0] == "wal":
        return
    try:
        connection.execute("PRAGMA journal_mode = WAL")
    except sqlite3.OperationalError as error:
        if "locked" not in str(error):
            raise


def _checked(connection: sqlite3.Connection, path: Path) -> int:
    """The schema version of an empty or own database; :class:`StoreError` for any other.

    The three values are read in one read transaction: read one by one, another
    process's creation committed between them showed a half-made file (no application
    ID, yet a version or tables) and this refused it as another program's.
    """
    alone = not connection.in_transaction
    if alone:
        connection.execute("BEGIN")
    try:
        application = connection.execute("PRAGMA application_id").fetchone()[0]
        version = int(connection.execute("PRAGMA user_version").fetchone()[0])
        tables = connection.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
    finally:
        if alone:
            connection.execute("COMMIT")
    if application == 0 and version == 0:
        if tables:
            raise problem(path, ValueError("an SQLite file of another program, not a test history"))
        return 0
    if application != APPLICATION_ID:
        raise problem(path, ValueError("an SQLite file of another program, not a test history"))
    if version > VERSION:
        raise problem(
            path,
            ValueError(
                f"schema version {version} of a newer ros-isolated-test (this reads {VERSION})"
            ),
        )
    return version


def keep(connection: sqlite3.Connection) -> int:
    """How many runs the database keeps (``history prune --keep``), else the default."""
    row = connection.execute("SELECT value FROM meta WHERE key = 'keep'").fetchone()
    return int(row[0]) if row else DEFAULT_KEEP


def prune(connection: sqlite3.Connection, runs: int | None = None, tidy: bool = False) -> int:
    """Drop all but the newest ``runs`` runs (the kept number when None); how many went.

    Called inside a transaction by the recorder, or alone by ``history prune``, which
    also ``tidy``-ies: drops the names of tests no kept run has (a scan of every
    attempt, too slow to pay at each recording) and gives the freed pages back.
    """
    alone = not connection.in_transaction
    if alone:
        connection.execute("BEGIN IMMEDIATE")
    try:
        if runs is None:
            runs = keep(connection)
        else:
            connection.execute("INSERT OR REPLACE INTO meta VALUES ('keep', ?)", (str(runs),))
        old = [
            row[0]
            for row in connection.execute(
                "SELECT id FROM runs ORDER BY started DESC, id DESC LIMIT -1 OFFSET ?", (runs,)
            )
        ]
        for run in old:
            connection.execute("DELETE FROM attempts WHERE run = ?", (run,))
            connection.execute("DELETE FROM runs WHERE id = ?", (run,))
        if tidy:
            connection.execute(
                "DELETE FROM tests WHERE id NOT IN (SELECT DISTINCT test FROM attempts)"
            )
        if alone:
            connection.execute("COMMIT")
        if tidy:
            connection.execute("VACUUM")
    except BaseException:
        if alone:
            connection.execute("ROLLBACK")
        raise
    return len(old)


def stored(text: str) -> str | bytes:
    """``text`` as the database keeps it: as text, or its UTF-8 bytes when it has surrogates.

    A name that was not UTF-8 on disk keeps its lone surrogates (as ``shard.identity``
    encodes them); SQLite text cannot hold those, so such a name is a blob, read back
    by :func:`loaded` as the same string.
    """
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return text.encode("utf-8", "surrogatepass")
    return text


def loaded(value: str | bytes) -> str:
    """A name as :func:`stored` kept it, back as the string it was."""
    return value.decode("utf-8", "surrogatepass") if isinstance(value, bytes) else value
