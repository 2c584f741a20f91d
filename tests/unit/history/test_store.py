"""The history database: created at the current schema, migrated from older, others refused."""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from pathlib import Path

import pytest

from ros_isolated_test.history import store


def test_a_new_database_is_ours_at_the_current_schema_in_wal_mode(tmp_path: Path) -> None:
    db = tmp_path / "h.sqlite3"
    store.connect(db).close()
    with sqlite3.connect(db) as raw:
        assert raw.execute("PRAGMA application_id").fetchone()[0] == store.APPLICATION_ID
        assert raw.execute("PRAGMA user_version").fetchone()[0] == store.VERSION
        assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    raw.close()


def test_a_version_1_database_is_migrated_keeping_its_runs(tmp_path: Path) -> None:
    db = tmp_path / "old.sqlite3"
    raw = sqlite3.connect(db)
    raw.executescript(store.MIGRATIONS[0])
    raw.execute(f"PRAGMA application_id = {store.APPLICATION_ID}")
    raw.execute("PRAGMA user_version = 1")
    raw.execute("INSERT INTO runs (key, started) VALUES ('k', '2026-01-01')")
    raw.commit()
    raw.close()
    with pytest.raises(store.StoreError, match="schema version 1"):
        store.connect(db, write=False)  # a reader never migrates
    connection = store.connect(db)
    assert connection.execute("PRAGMA user_version").fetchone()[0] == store.VERSION
    assert connection.execute("SELECT key, recorded FROM runs").fetchall() == [("k", "")]
    connection.close()


@pytest.mark.parametrize(
    ("made", "said"),
    [
        ("foreign", "another program"),
        ("newer", "newer ros-isolated-test"),
        ("corrupt", "not a database"),
    ],
)
def test_a_database_not_ours_is_refused_unchanged(tmp_path: Path, made: str, said: str) -> None:
    db = tmp_path / "x.sqlite3"
    if made == "corrupt":
        db.write_bytes(b"\x01" * 4096)
    else:
        raw = sqlite3.connect(db)
        raw.execute("CREATE TABLE mine (x)")
        if made == "newer":
            raw.execute(f"PRAGMA application_id = {store.APPLICATION_ID}")
            raw.execute(f"PRAGMA user_version = {store.VERSION + 1}")
        raw.commit()
        raw.close()
    before = db.read_bytes()
    with pytest.raises(store.StoreError, match=said) as caught:
        store.connect(db)
    assert str(db) in str(caught.value) and "\n" not in str(caught.value)
    assert db.read_bytes() == before
    store.connect(tmp_path / "fresh.sqlite3").close()  # control: a new file is fine


def _empty_wal_file(db: Path) -> None:
    """An empty database in WAL mode: a creator that stopped before its schema."""
    raw = sqlite3.connect(db, isolation_level=None)
    raw.execute("PRAGMA journal_mode = WAL")
    raw.close()


def test_a_database_created_meanwhile_by_another_is_not_taken_for_a_foreign_one(
    tmp_path: Path,
) -> None:
    created: list[str] = []

    def create_before_the_version_is_read(db: Path) -> Callable[[str], None]:
        def traced(statement: str) -> None:
            if "user_version" in statement and not created:
                created.append(statement)
                store.connect(db).close()  # another recorder creates it between two reads

        return traced

    # Control: read one by one, the file looks half made (no application ID, a version).
    control = tmp_path / "control.sqlite3"
    _empty_wal_file(control)
    reader = sqlite3.connect(control, isolation_level=None)
    reader.set_trace_callback(create_before_the_version_is_read(control))
    application = reader.execute("PRAGMA application_id").fetchone()[0]
    version = reader.execute("PRAGMA user_version").fetchone()[0]
    reader.close()
    assert created and (application, version) == (0, store.VERSION)

    created.clear()
    db = tmp_path / "h.sqlite3"
    _empty_wal_file(db)
    checker = sqlite3.connect(db, isolation_level=None)
    checker.set_trace_callback(create_before_the_version_is_read(db))
    store._shaped(checker, db, write=True)  # the same interleaving: no "another program"
    assert created
    assert checker.execute("PRAGMA application_id").fetchone()[0] == store.APPLICATION_ID
    assert checker.execute("PRAGMA user_version").fetchone()[0] == store.VERSION
    checker.close()


def test_a_database_being_written_opens_and_the_next_writer_puts_it_in_wal_mode(
    tmp_path: Path,
) -> None:
    db = tmp_path / "h.sqlite3"
    store.connect(db).close()
    raw = sqlite3.connect(db, isolation_level=None)
    raw.execute("PRAGMA journal_mode = DELETE")
    raw.execute("BEGIN IMMEDIATE")  # another recorder is writing
    other = sqlite3.connect(db, isolation_level=None)
    with pytest.raises(sqlite3.OperationalError, match="locked"):
        other.execute("PRAGMA journal_mode = WAL")  # control: SQLite refuses the switch now
    other.close()
    store.connect(db).close()  # opens all the same, in rollback mode for now
    assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    raw.execute("COMMIT")
    raw.close()
    store.connect(db).close()
    with sqlite3.connect(db) as after:
        assert after.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    after.close()


def test_prune_keeps_the_newest_runs_and_remembers_how_many(tmp_path: Path) -> None:
    connection = store.connect(tmp_path / "h.sqlite3")
    for day in range(1, 6):
        connection.execute(
            "INSERT INTO runs (key, started) VALUES (?, ?)", (str(day), f"2026-01-0{day}")
        )
    assert store.prune(connection, 3, tidy=True) == 2
    assert [row[0] for row in connection.execute("SELECT key FROM runs ORDER BY started")] == [
        "3",
        "4",
        "5",
    ]
    assert store.keep(connection) == 3
    assert store.prune(connection) == 0
    connection.close()


def test_a_name_that_was_not_utf8_comes_back_the_same() -> None:
    for name in ("pkg/plain", "pkg/not-utf8-\udcff"):
        assert store.loaded(store.stored(name)) == name
