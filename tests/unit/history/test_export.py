"""Export: every attempt as a JSON line; durations as the median of the window."""

from __future__ import annotations

import json
from pathlib import Path

from helpers.split_trees import START, runner_file

from ros_isolated_test.history import export, record, store


def test_json_lines_and_durations(tmp_path: Path) -> None:
    db = tmp_path / "h.sqlite3"
    for k, seconds in enumerate((1.0, 3.0, 2.0)):
        runner_file(tmp_path / f"run{k}", "pkg/a", seconds, started=START + k)
        record.record(db, [tmp_path / f"run{k}"])
    connection = store.connect(db, write=False)
    lines = [json.loads(line) for line in export.json_lines(connection)]
    assert [line["seconds"] for line in lines] == [1.0, 3.0, 2.0]
    assert {line["test"] for line in lines} == {"pkg/a"}
    found = export.durations(connection)
    connection.close()
    assert "pkg/a" in found and found.ordered() == ["pkg/a"]
