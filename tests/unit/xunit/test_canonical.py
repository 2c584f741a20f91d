"""``xunit.canonical``: any producer's file made canonical, named for the test it belongs to.

The runner adopts the file its test wrote and ``ros-isolated-test normalise`` rewrites a
file nobody ran here; both read it the same way, so the suite is named
``<package>.<test>`` from the file's name, the original's name and the reader's repairs
are kept as properties, and a canonical file normalised again is unchanged; ``normalise
-o`` writes it where asked, never over a FIFO or a device. The reader (and lxml) is
loaded only once a file is read.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers.canonical import check_canonical
from helpers.results import CaseResult
from helpers.xunit import (
    SAMPLES,
    attempts_of,
    case_node,
    failed,
    modules_loaded,
    parse,
    passed,
    properties_of,
    suite_of,
)
from lxml import etree

from ros_isolated_test.xunit import canonical, serialise
from ros_isolated_test.xunit.attempts import ATTEMPTS_KEPT, merge_attempts
from ros_isolated_test.xunit.canonical import OutputError, normalise_file, normalise_to, read_cases
from ros_isolated_test.xunit.model import Outcome


@pytest.mark.parametrize(
    ("file", "test"),
    [
        ("talker.gtest.xml", "talker"),
        ("talker.xunit.xml", "talker"),
        ("talker.xml", "talker"),
        ("talker.v2.xml", "talker.v2"),
        ("notes.txt", "notes.txt"),
        (".xml", ".xml"),  # a suffix alone is a name, not an empty one
    ],
)
def test_a_test_is_named_after_its_file_without_the_producers_suffix(file: str, test: str) -> None:
    assert canonical.test_name_of(Path("build") / "pkg" / file) == test


def test_a_producers_file_becomes_the_canonical_suite_of_its_test(tmp_path: Path) -> None:
    source = tmp_path / "gtest-1.17.0_mixed.gtest.xml"
    source.write_bytes((SAMPLES / source.name).read_bytes())
    data, failing = normalise_file(source, "pkg", canonical.test_name_of(source))
    out = tmp_path / "canonical.xml"
    out.write_bytes(data)
    result = check_canonical(out, "pkg", "gtest-1.17.0_mixed")
    assert failing and result.counts[1] > 0
    assert result.properties["original_result_file"] == source.name
    # Control: a file of passed cases is canonical and does not fail.
    source.write_bytes((SAMPLES / "ament_run_test_success_result.xml").read_bytes())
    data, failing = normalise_file(source, "pkg", "ok")
    assert not failing
    assert [case.outcome for case in _read_back(tmp_path, data, "ok")] == ["passed"]


def _read_back(tmp_path: Path, data: bytes, test: str) -> tuple[CaseResult, ...]:
    out = tmp_path / f"{test}.canonical.xml"
    out.write_bytes(data)
    return check_canonical(out, "pkg", test).summary.cases


def test_what_the_reader_repaired_is_said_in_a_property(tmp_path: Path) -> None:
    source = tmp_path / "t.xml"
    source.write_bytes(b'<testsuite name="s"><testcase classname="C" name="bad\xff"/></testsuite>')
    data, _ = normalise_file(source, "pkg", "t")
    assert "were written as \\xNN" in properties_of(parse(data))["result_file_repairs"]
    source.write_bytes(b'<testsuite name="s"><testcase classname="C" name="good"/></testsuite>')
    data, _ = normalise_file(source, "pkg", "t")
    # The control: nothing to repair, nothing said.
    assert "result_file_repairs" not in properties_of(parse(data))


def test_read_cases_gives_the_cases_and_what_reading_found(tmp_path: Path) -> None:
    source = tmp_path / "t.xml"
    source.write_text('<testsuite name="s"><testcase classname="C" name="a"/>')
    cases, read = read_cases(source, "pkg", "t")
    assert [(case.classname, case.name, case.outcome) for case in cases] == [
        ("pkg.C", "a", Outcome.PASSED),
        ("pkg.t", "result file", Outcome.ERROR),
    ]
    assert read.problems and read.path == source
    source.write_text('<testsuite name="s"><testcase classname="C" name="a"/></testsuite>')
    cases, read = read_cases(source, None, "t")
    assert [(case.classname, case.name) for case in cases] == [("C", "a")]
    assert read.problems == []


def test_normalise_to_writes_where_asked_and_never_replaces_a_special_file(
    tmp_path: Path,
) -> None:
    """``ros-isolated-test normalise -o``: the test is named after the file it reads."""
    source = tmp_path / "talker.gtest.xml"
    source.write_bytes((SAMPLES / "gtest-1.17.0_mixed.gtest.xml").read_bytes())
    output = tmp_path / "canonical.xml"
    data, failing = normalise_to(source, output, "pkg")
    assert output.read_bytes() == data and failing
    assert check_canonical(output, "pkg", "talker").counts[1] > 0
    assert normalise_to(source, None, "pkg", "other")[0] != data  # named as asked, not written
    assert normalise_to(source, Path(os.devnull), "pkg")[1]
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    with pytest.raises(OutputError, match="it is a FIFO"):
        normalise_to(source, fifo, "pkg")
    assert fifo.exists() and not fifo.is_file()


def test_lxml_is_loaded_only_once_a_file_is_read(tmp_path: Path) -> None:
    """A test that wrote no file of its own never pays for the reader."""
    source = tmp_path / "t.xml"
    source.write_text('<testsuite name="s"><testcase classname="C" name="a"/></testsuite>')
    imported = "from pathlib import Path\nfrom ros_isolated_test.xunit import canonical"
    assert modules_loaded(imported, "lxml") == [False]
    read = f"{imported}\ncanonical.read_cases(Path({str(source)!r}), 'pkg', 't')"
    assert modules_loaded(read, "lxml") == [True]  # the control: reading does load it


def _testcases(data: bytes) -> list[bytes]:
    return [etree.tostring(node) for node in parse(data).iter("testcase")]


@pytest.mark.parametrize("final", [Outcome.PASSED, Outcome.FAILURE])
@pytest.mark.parametrize("count", [2, ATTEMPTS_KEPT + 2, 50])
def test_a_canonical_file_normalised_again_keeps_its_cases(
    tmp_path: Path, count: int, final: Outcome
) -> None:
    """What ``ros-isolated-test normalise`` does to a file the runner wrote: nothing."""
    last = passed() if final is Outcome.PASSED else failed(message="last")
    history = [suite_of([failed(message=f"attempt {n}")]) for n in range(1, count)]
    canonical = serialise.serialize(merge_attempts([*history, suite_of([last])]))
    source = tmp_path / "canonical.xml"
    written = canonical
    for _ in range(2):
        source.write_bytes(written)
        again, _ = normalise_file(source, "pkg", "test")
        assert _testcases(again) == _testcases(canonical)
        written = again
    node = case_node(parse(canonical), "a")
    assert len(attempts_of(node)) == min(count - 1, ATTEMPTS_KEPT)
    if final is Outcome.PASSED:
        # The note says how many failed and, when some were cut, which are shown.
        shown = "each is" if count - 1 <= ATTEMPTS_KEPT else "the first 5 and the last 5 are"
        note = f"Passed after {count - 1} failed attempt(s); {shown} recorded below."
        assert node.findtext("system-out") == note
