"""Databases merged by run and test identity: twice changes nothing; a foreign one refused."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.split_trees import START, runner_file

from ros_isolated_test.history import merge, record, store
from ros_isolated_test.history.export import json_lines


def _lines(db: Path) -> list[str]:
    connection = store.connect(db, write=False)
    try:
        return list(json_lines(connection))
    finally:
        connection.close()


def test_merged_twice_is_merged_once(tmp_path: Path) -> None:
    for k in range(2):
        runner_file(tmp_path / f"run{k}", "pkg/a", 1.0, started=START + k)
    record.record(tmp_path / "a.sqlite3", [tmp_path / "run0"])
    record.record(tmp_path / "b.sqlite3", [tmp_path / "run1"])
    record.record(tmp_path / "both.sqlite3", [tmp_path / "run0"])
    record.record(tmp_path / "both.sqlite3", [tmp_path / "run1"])
    out = tmp_path / "out.sqlite3"
    assert merge.merge(out, [tmp_path / "a.sqlite3", tmp_path / "b.sqlite3"]) == 2
    assert merge.merge(out, [tmp_path / "a.sqlite3", tmp_path / "b.sqlite3"]) == 0
    assert _lines(out) == _lines(tmp_path / "both.sqlite3")


def test_a_source_that_is_no_history_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.sqlite3"
    bad.write_bytes(b"\x03" * 1024)
    with pytest.raises(store.StoreError, match=r"bad\.sqlite3"):
        merge.merge(tmp_path / "out.sqlite3", [bad])
