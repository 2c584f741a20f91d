"""``shard.durations``: the file written sorted and rounded, read strictly, merged by median.

Every bad file is one line naming the variable or option, the file, what is wrong and the
fix; beside each, the control: the same file made right is read.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from pathlib import Path

import pytest

from ros_isolated_test import atomic_file
from ros_isolated_test.shard import durations
from ros_isolated_test.shard.durations import (
    DURATIONS_ENV,
    MAX_SECONDS,
    Durations,
    DurationsError,
    load,
    measured,
    merge,
    rounded,
    write,
)
from ros_isolated_test.shard.spec import ShardSettingError

GOOD = {"version": 1, "durations": {"pkg/test_a": 1.5, "pkg/test_b": 12}}


def _file(tmp_path: Path, content: object, name: str = "durations.json") -> Path:
    path = tmp_path / name
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    return path


def _error(path: Path, origin: str = DURATIONS_ENV) -> str:
    with pytest.raises(DurationsError) as raised:
        load(path, origin)
    message = str(raised.value)
    assert "\n" not in message
    assert message.startswith(f"{origin}={path}: ") or message.startswith(f"{origin} {path}: ")
    assert "to split by count" in message  # the fix
    assert isinstance(raised.value, ShardSettingError)
    return message


# --- rounding ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("seconds", "us"),
    [
        (0, 0),
        (0.0000004, 0),
        (0.000007, 7),  # below 100 us: to the microsecond
        (0.000099, 99),
        (0.000317, 320),  # a quick pytest item: two figures, never 0
        (0.0004, 400),
        (0.0012345, 1200),
        (0.0456, 46000),
        (0.099, 99000),
        (0.1234, 120000),
        (0.456, 460000),
        (1.0, 1000000),
        (1.25, 1300000),  # half up
        (12.34, 12000000),
        (99.6, 100000000),
        (1234.5, 1200000000),
        (MAX_SECONDS, 600000000000),
    ],
)
def test_a_measurement_keeps_two_significant_figures(seconds: float, us: int) -> None:
    assert rounded(seconds) == us


def test_rounding_keeps_every_value_within_five_percent() -> None:
    for tenths in range(1, 100000, 7):
        for seconds in (tenths / 10 + 0.0123, tenths / 1e7 + 0.0000123):
            assert abs(rounded(seconds) / 1e6 - seconds) <= 0.05 * seconds


def test_a_rerun_with_noise_changes_few_lines() -> None:
    """What the rounding is for: 1% noise moves few values, full precision would move all."""
    before = {f"pkg/t{number}": 0.5 + number * 0.37 for number in range(200)}
    after = {key: value * 1.01 for key, value in before.items()}
    lines = measured(before).text().splitlines()
    changed = set(lines) ^ set(measured(after).text().splitlines())
    assert len(changed) // 2 < 0.6 * len(before)
    assert len(changed) > 0  # control: some did move
    raw = {json.dumps(before[key]) != json.dumps(after[key]) for key in before}
    assert raw == {True}  # control: unrounded, every line would


@pytest.mark.parametrize("seconds", [-0.001, float("nan"), float("inf"), MAX_SECONDS + 1])
def test_no_measurement_out_of_range_is_rounded(seconds: float) -> None:
    with pytest.raises(ValueError, match="seconds"):
        rounded(seconds)


# --- writing ------------------------------------------------------------------------------


def test_the_file_is_sorted_one_test_a_line_with_its_version(tmp_path: Path) -> None:
    path = tmp_path / "out" / "durations.json"
    write(path, measured({"zeta/t": 1.23, "alpha/t2": 45.6, "alpha/t10": 0.0456, "b/n::x": 0}))
    assert path.read_text() == (
        "{\n"
        '  "version": 1,\n'
        '  "durations": {\n'
        '    "alpha/t10": 0.046,\n'
        '    "alpha/t2": 46,\n'
        '    "b/n::x": 0,\n'
        '    "zeta/t": 1.2\n'
        "  }\n"
        "}\n"
    )
    assert load(path) == measured(
        {"zeta/t": 1.23, "alpha/t2": 45.6, "alpha/t10": 0.0456, "b/n::x": 0}
    )


def test_an_empty_file_is_written_and_read(tmp_path: Path) -> None:
    path = tmp_path / "durations.json"
    write(path, Durations({}))
    assert json.loads(path.read_text()) == {"version": 1, "durations": {}}
    assert len(load(path)) == 0


def test_what_is_written_is_read_back_exactly(tmp_path: Path) -> None:
    odd = {'pkg/é "quoted" \\ \n tab\t': 3.3, "pkg/\udcff": 0.5, "pkg/test/a.py::b[1/2]": 7}
    path = tmp_path / "durations.json"
    write(path, measured(odd))
    assert path.read_bytes().isascii()  # every identity escaped: the file is ASCII
    assert load(path) == measured(odd)


def test_writing_replaces_the_file_whole_and_never_a_device(tmp_path: Path) -> None:
    path = tmp_path / "durations.json"
    path.write_text("old")
    write(path, measured({"p/t": 1}))
    assert load(path) == measured({"p/t": 1})
    assert [item.name for item in tmp_path.iterdir()] == ["durations.json"]  # no temp left
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(
        DurationsError, match=r"^--durations .*fifo: cannot write it: .*regular file"
    ):
        write(fifo, measured({"p/t": 1}))
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    assert atomic_file.special_kind(fifo) == "a FIFO"


@pytest.mark.parametrize("under", ["durations.json", "deeper/durations.json"])
def test_writing_under_a_file_names_the_file_in_the_way(tmp_path: Path, under: str) -> None:
    """Not the system's "File exists" (mkdir's word): the parent that is a file."""
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    with pytest.raises(DurationsError) as raised:
        write(blocker / under, measured({"p/t": 1}))
    assert str(raised.value) == (
        f"--durations {blocker / under}: cannot write it: {blocker} is a file, not a folder; "
        "name a path in a folder instead"
    )
    # The control: the same name in a folder that is missing is made, and written.
    write(tmp_path / "folder" / under, measured({"p/t": 1}))
    assert load(tmp_path / "folder" / under) == measured({"p/t": 1})


def test_writing_where_no_file_can_be_is_one_line(tmp_path: Path) -> None:
    folder = tmp_path / "a_folder"
    (folder / "inside").mkdir(parents=True)  # a folder that is not empty: no file replaces it
    with pytest.raises(DurationsError, match=r"cannot write it: .*; choose a writable file path$"):
        write(folder, measured({"p/t": 1}))


# --- reading: controls first, then every way a file can be wrong ---------------------------


def test_a_good_file_is_read(tmp_path: Path) -> None:
    loaded = load(_file(tmp_path, GOOD))
    assert loaded.micros == {"pkg/test_a": 1500000, "pkg/test_b": 12000000}
    assert list(loaded) == ["pkg/test_a", "pkg/test_b"]
    assert "pkg/test_a" in loaded
    assert "pkg/test_c" not in loaded


def test_a_file_with_a_byte_order_mark_and_any_spacing_is_read(tmp_path: Path) -> None:
    path = tmp_path / "durations.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(GOOD, indent=7).encode())
    assert load(path) == load(_file(tmp_path, GOOD, "plain.json"))


def test_a_value_is_read_to_the_microsecond(tmp_path: Path) -> None:
    content = {"p/t": 1.2345674, "p/u": 3, "p/v": 0.000317, "p/w": 0.0000004, "p/x": 0.045}
    loaded = load(_file(tmp_path, {"version": 1, "durations": content}))
    assert loaded.micros == {"p/t": 1234567, "p/u": 3000000, "p/v": 317, "p/w": 0, "p/x": 45000}


def test_a_quick_test_is_written_and_read_back_to_the_microsecond(tmp_path: Path) -> None:
    """The pile-up of issue 41: a 0.3 ms item was written as 0."""
    path = tmp_path / "durations.json"
    write(path, measured({"p/quick": 0.000317, "p/quicker": 0.0000071, "p/slow": 2.0}))
    assert json.loads(path.read_text())["durations"] == {
        "p/quick": 0.00032,
        "p/quicker": 0.000007,
        "p/slow": 2,
    }
    assert '"p/quick": 0.00032,' in path.read_text()  # no exponent: six decimals at most
    assert load(path).micros == {"p/quick": 320, "p/quicker": 7, "p/slow": 2000000}


def test_a_file_written_to_the_millisecond_reads_as_before(tmp_path: Path) -> None:
    """An older version's file: the same seconds, written back alike; named by today's rules."""
    old = (
        '{\n  "version": 1,\n  "durations": {\n    "p/a": 0.045,\n    "p/b": 0,\n'
        '    "p/c": 1.2,\n    "p/d": 310\n  }\n}\n'
    )
    path = _file(tmp_path, old)
    loaded = load(path)
    assert loaded.micros == {"p/a": 45000, "p/b": 0, "p/c": 1200000, "p/d": 310000000}
    # To the millisecond as before, with the placement rules it is planned by.
    canonical = (
        b'{"durations":{"p/a":45,"p/b":0,"p/c":1200,"p/d":310000},"placement":2,"version":1}'
    )
    assert loaded.fingerprint == hashlib.sha256(canonical).hexdigest()[:16]
    write(tmp_path / "again.json", loaded)
    assert (tmp_path / "again.json").read_text() == old


def test_a_missing_file(tmp_path: Path) -> None:
    message = _error(tmp_path / "nowhere.json")
    assert "cannot open it: No such file or directory" in message


def test_an_unreadable_file(tmp_path: Path) -> None:
    path = _file(tmp_path, GOOD)
    path.chmod(0)
    if os.access(path, os.R_OK):  # root reads anything: the directory case stands in
        path = tmp_path
        assert "it is a directory" in _error(path)
        return
    assert "cannot open it: Permission denied" in _error(path)


def test_a_directory(tmp_path: Path) -> None:
    assert "it is a directory" in _error(tmp_path)


def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    assert "it is not a regular file" in _error(fifo)


def test_a_file_too_large(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = _file(tmp_path, GOOD)
    monkeypatch.setattr(durations, "MAX_FILE_BYTES", path.stat().st_size - 1)
    assert "larger than" in _error(path)
    monkeypatch.setattr(durations, "MAX_FILE_BYTES", path.stat().st_size)
    assert len(load(path)) == 2  # control: at the limit it is read


@pytest.mark.parametrize(
    ("content", "said"),
    [
        ("", "it is not JSON: Expecting value: line 1 column 1"),
        ('{"version": 1, "durations": {', "it is not JSON"),
        (b"{\xff}", "it is not UTF-8 text (byte 1)"),
        ("[" * 100000 + "]" * 100000, "nests too deeply"),
        ('{"version": 1, "durations": {"p/t": NaN}}', "NaN is not a finite number"),
        ('{"version": 1, "durations": {"p/t": Infinity}}', "Infinity is not a finite number"),
        ('{"version": 1, "durations": {"p/t": 1e999}}', "inf is not a finite number"),
        ('{"version": 1, "durations": {"p/t": -1e999}}', "-inf is not a finite number"),
        ('{"version": 1, "durations": {"p/t": 1, "p/t": 2}}', "'p/t' is listed twice"),
        ('{"version": 1, "version": 1, "durations": {}}', "'version' is listed twice"),
        ("[]", "it holds a JSON list, not an object"),
        ('"durations"', "it holds a JSON str"),
        ('{"durations": {}}', "it has no version"),
        ('{"version": 2, "durations": {}}', "format version 2 is not 1"),
        ('{"version": "1", "durations": {}}', "format version '1' is not 1"),
        ('{"version": true, "durations": {}}', "format version True is not 1"),
        ('{"version": 1.0, "durations": {}}', "format version 1.0 is not 1"),
        ('{"version": 1}', "its durations are not an object"),
        ('{"version": 1, "durations": []}', "its durations are not an object"),
        ('{"version": 1, "durations": {}, "tests": 3}', "unknown key 'tests'"),
        ('{"version": 1, "durations": {"no_slash": 1}}', "is not <package>/<test>"),
        ('{"version": 1, "durations": {"/t": 1}}', "is not <package>/<test>"),
        ('{"version": 1, "durations": {"p/": 1}}', "is not <package>/<test>"),
        ('{"version": 1, "durations": {"p/t": "12"}}', "test 'p/t': '12' is not a number"),
        ('{"version": 1, "durations": {"p/t": null}}', "None is not a number"),
        ('{"version": 1, "durations": {"p/t": true}}', "True is not a number"),
        ('{"version": 1, "durations": {"p/t": [1]}}', "[1] is not a number"),
        ('{"version": 1, "durations": {"p/t": -0.5}}', "test 'p/t': -0.5 seconds is negative"),
        ('{"version": 1, "durations": {"p/t": 604801}}', "more than a week"),
        ('{"version": 1, "durations": {"p/t": 1e300}}', "more than a week"),
        ('{"version": 1, "durations": {"p/t": ' + "9" * 5000 + "}}", "not a durations file"),
    ],
)
def test_a_malformed_file_is_one_line_saying_what_is_wrong(
    tmp_path: Path, content: str | bytes, said: str
) -> None:
    path = tmp_path / "durations.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    assert said in _error(path)


def test_a_test_name_may_end_in_a_slash(tmp_path: Path) -> None:
    path = _file(tmp_path, {"version": 1, "durations": {"pkg/dir/": 1, "pkg/t": 2}})
    assert load(path).micros == {"pkg/dir/": 1000000, "pkg/t": 2000000}
    # Control: a package with no name after its "/" is refused.
    assert "is not <package>/<test>" in _error(
        _file(tmp_path, {"version": 1, "durations": {"pkg/": 1}})
    )


def test_the_one_wrong_test_among_many_is_named(tmp_path: Path) -> None:
    tests: dict[str, object] = {f"pkg/t{number}": number / 10 for number in range(5000)}
    path = _file(tmp_path, {"version": 1, "durations": tests})
    assert len(load(path)) == 5000  # control: all good
    tests["pkg/t4321"] = -1
    path = _file(tmp_path, {"version": 1, "durations": tests})
    assert "test 'pkg/t4321': -1 seconds is negative" in _error(path)


def test_a_control_character_in_a_bad_key_cannot_forge_a_line(tmp_path: Path) -> None:
    path = _file(tmp_path, {"version": 1, "durations": {"p/t\nforged: line": -1}})
    assert "forged" in _error(path)  # on the one line, escaped


def test_an_option_is_named_as_an_option(tmp_path: Path) -> None:
    message = _error(tmp_path / "nowhere.json", "--durations")
    assert message.startswith(f"--durations {tmp_path / 'nowhere.json'}: ")
    assert "leave out --durations to split by count" in message


# --- fingerprint -----------------------------------------------------------------------------


def test_the_fingerprint_is_of_the_content_not_the_bytes(tmp_path: Path) -> None:
    spaced = _file(tmp_path, json.dumps(GOOD, indent=9), "spaced.json")
    reordered = _file(
        tmp_path, {"durations": {"pkg/test_b": 12.0, "pkg/test_a": 1.5}, "version": 1}, "other.json"
    )
    assert (
        load(spaced).fingerprint
        == load(reordered).fingerprint
        == load(_file(tmp_path, GOOD)).fingerprint
    )
    changed = {"version": 1, "durations": {"pkg/test_a": 1.6, "pkg/test_b": 12}}
    assert load(_file(tmp_path, changed, "changed.json")).fingerprint != load(spaced).fingerprint


def test_the_fingerprint_is_sha256_of_the_canonical_form() -> None:
    """Pinned: the same on every machine and Python; another placement, another name."""
    loaded = Durations({"pkg/test_a": 1500000, "pkg/test_b": 12000000})
    canonical = b'{"durations":{"pkg/test_a":1500,"pkg/test_b":12000},"placement":2,"version":1}'
    assert loaded.fingerprint == hashlib.sha256(canonical).hexdigest()[:16]
    # Control: the name the same content had under the rules before (placement 1, unsaid).
    before = b'{"durations":{"pkg/test_a":1500,"pkg/test_b":12000},"version":1}'
    assert hashlib.sha256(before).hexdigest()[:16] == "73a3e8586c369f12" != loaded.fingerprint
    assert Durations({}).fingerprint != loaded.fingerprint
    # A value finer than a millisecond: in microseconds, the unit said.
    finer = Durations({"pkg/test_a": 1500000, "pkg/test_b": 317})
    canonical = (
        b'{"durations":{"pkg/test_a":1500000,"pkg/test_b":317},"placement":2,'
        b'"unit":"us","version":1}'
    )
    assert finer.fingerprint == hashlib.sha256(canonical).hexdigest()[:16]
    # Control: no two contents share one form (1.5 s and 317 us is not 1500 and 0.317 ms).
    assert finer.fingerprint != Durations({"pkg/test_a": 1500000, "pkg/test_b": 0}).fingerprint


# --- merging ------------------------------------------------------------------------------


def test_shards_of_one_run_merge_into_their_union() -> None:
    one = measured({"a/t1": 1, "a/t2": 2})
    two = measured({"b/t3": 3})
    assert merge([one, two]) == measured({"a/t1": 1, "a/t2": 2, "b/t3": 3})


def test_a_test_of_several_runs_is_their_median() -> None:
    runs = [measured({"p/t": 10, "p/once": 5}), measured({"p/t": 11}), measured({"p/t": 300})]
    merged = merge(runs)
    assert merged.micros == {"p/t": 11000000, "p/once": 5000000}  # the timed-out 300 s is ignored
    assert merge(reversed(runs)) == merged  # the order does not matter
    two = merge([measured({"p/t": 10}), measured({"p/t": 13})])
    assert two.micros == {"p/t": 12000000}  # even: the mean of the middle two, rounded
    quick = merge([measured({"p/q": 0.000301}), measured({"p/q": 0.000342})])
    assert quick.micros == {"p/q": 320}  # the same below a millisecond


def test_merging_nothing_is_empty() -> None:
    assert len(merge([])) == 0


def test_measurements_need_identities() -> None:
    with pytest.raises(ValueError, match="<package>/<test>"):
        measured({"no_package": 1})


def test_equal_durations_are_equal_and_hash_alike() -> None:
    one, two = Durations({"p/a": 1, "p/b": 2}), Durations({"p/b": 2, "p/a": 1})
    assert one == two
    assert hash(one) == hash(two)
    assert one != Durations({"p/a": 1})
    assert "2 tests" in repr(one)
