"""``shard.record``: the record a machine of a split leaves, whole however many write it.

The bytes are JSON (ASCII, any host name), the same from every runner of a machine;
many writers at once leave one whole record; a record that is not one is named. A
record speaks for its run only: leaving one removes an earlier run's records of other
shares or plans in its folder; a record written before its results says ``started``.
"""

from __future__ import annotations

import json
import multiprocessing
from pathlib import Path

import pytest

from ros_isolated_test.shard import record
from ros_isolated_test.shard.selection import Selection, select
from ros_isolated_test.shard.spec import SHARD_ENV, Share


def _selection(share: str = "2/4") -> Selection:
    selection = select({SHARD_ENV: share})
    assert selection is not None
    return selection


@pytest.mark.parametrize("host", ["ci-7", 'odd"\\host\n', "hôte-😀", "bad\udcffname"])
def test_the_record_is_ascii_json_that_reads_back(tmp_path: Path, host: str) -> None:
    record.leave(tmp_path, _selection(), host, "1.2.3")
    path = tmp_path / "ros_isolated_test_shard-2-of-4.json"
    data = path.read_bytes()
    assert data.isascii()
    assert json.loads(data) == {
        "shard": "2/4", "index": 2, "total": 4, "plan": "count", "host": host, "version": "1.2.3",
    }  # fmt: skip
    found = record.read(path)
    assert isinstance(found, record.Record)
    assert (found.share, found.plan, found.host) == (Share(2, 4), "count", host)


def _leave_many(folder: str) -> None:
    for _ in range(200):
        record.leave(Path(folder), _selection("3/5"), "host", "1")


def test_many_writers_at_once_leave_one_whole_record(tmp_path: Path) -> None:
    workers = [multiprocessing.Process(target=_leave_many, args=(str(tmp_path),)) for _ in range(4)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(60)
    assert [worker.exitcode for worker in workers] == [0, 0, 0, 0]
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "ros_isolated_test_shard-3-of-5.json"
    ]
    assert isinstance(record.read(tmp_path / "ros_isolated_test_shard-3-of-5.json"), record.Record)


def test_a_record_already_there_as_it_would_be_is_not_written_again(tmp_path: Path) -> None:
    record.leave(tmp_path, _selection(), "host", "1")
    path = tmp_path / "ros_isolated_test_shard-2-of-4.json"
    before = path.stat().st_ino
    record.leave(tmp_path, _selection(), "host", "1")
    assert path.stat().st_ino == before
    # The control: another host's record replaces it (a rename: a new file).
    record.leave(tmp_path, _selection(), "other", "1")
    assert path.stat().st_ino != before


def test_a_record_left_removes_the_other_records_in_its_folder(tmp_path: Path) -> None:
    """An earlier run's records there (another share, another N) go; the control: other
    files, and a record in another folder, stay."""
    record.leave(tmp_path, _selection("3/4"), "host", "1")
    record.leave(tmp_path, _selection("1/2"), "host", "1")  # not there: a file of its own
    (tmp_path / "ros_isolated_test_shard-1-of-4.json").write_text("{")
    (tmp_path / "t.xml").write_text("<testsuite/>")
    (tmp_path / "sub").mkdir()
    record.leave(tmp_path / "sub", _selection("3/4"), "host", "1")
    assert sorted(path.name for path in tmp_path.glob("*.json")) == [
        "ros_isolated_test_shard-1-of-2.json", "ros_isolated_test_shard-1-of-4.json"
    ]  # fmt: skip
    record.leave(tmp_path, _selection("2/4"), "host", "1")
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "ros_isolated_test_shard-2-of-4.json", "sub", "t.xml"
    ]  # fmt: skip
    assert [path.name for path in (tmp_path / "sub").iterdir()] == [
        "ros_isolated_test_shard-3-of-4.json"
    ]
    # Already there as it would be written: the others go all the same.
    (tmp_path / "ros_isolated_test_shard-4-of-4.json").write_text("{}")
    record.leave(tmp_path, _selection("2/4"), "host", "1")
    assert not (tmp_path / "ros_isolated_test_shard-4-of-4.json").exists()


def test_a_started_record_says_so_and_one_without_a_state_is_complete(tmp_path: Path) -> None:
    path = tmp_path / "ros_isolated_test_shard-2-of-4.json"
    record.leave(tmp_path, _selection(), "host", "1", started=True)
    assert json.loads(path.read_bytes())["state"] == "started"
    found = record.read(path)
    assert isinstance(found, record.Record) and found.started
    # Completed: the bytes every RUNNER writes, no state (as records before states were).
    record.leave(tmp_path, _selection(), "host", "1")
    assert "state" not in json.loads(path.read_bytes())
    found = record.read(path)
    assert isinstance(found, record.Record) and not found.started
    path.write_text('{"index": 2, "total": 4, "plan": "count", "state": "odd"}')
    said = record.read(path)
    assert isinstance(said, str) and "state 'odd'" in said, said


@pytest.mark.parametrize(
    ("name", "content", "says"),
    [
        ("ros_isolated_test_shard-1-of-2.json", "{", "not JSON"),
        ("ros_isolated_test_shard-1-of-2.json", "[1]", "not a JSON object"),
        (
            "ros_isolated_test_shard-1-of-2.json",
            '{"index": 3, "total": 2, "plan": "x"}',
            "no share",
        ),
        (
            "ros_isolated_test_shard-1-of-2.json",
            '{"index": 2, "total": 2, "plan": "x"}',
            "its name",
        ),
    ],
    ids=["not-json", "a-list", "index-above-total", "name-differs"],
)
def test_a_record_that_is_not_one_is_named(
    tmp_path: Path, name: str, content: str, says: str
) -> None:
    path = tmp_path / name
    path.write_text(content)
    found = record.read(path)
    assert isinstance(found, str) and says in found, found


def test_record_names_are_told_from_other_files() -> None:
    assert record.is_record("ros_isolated_test_shard-12-of-40.json")
    for name in ("ros_isolated_test_shard-1-of-2.xml", "ros_isolated_test_shard-x-of-2.json",
                 "pytest.xml", "ros_isolated_test_shard-1-2.json"):  # fmt: skip
        assert not record.is_record(name), name
    assert record.file_name(Share(12, 40)) == "ros_isolated_test_shard-12-of-40.json"
