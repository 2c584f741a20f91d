"""``xunit.reader``: any result file read as far as it can be, and every reader agreeing on it.

A test's result file may be broken or hostile, or something other than a file; the
reader never raises for what the file holds, says what was wrong in ``problems`` and
keeps whatever came before it. Real suites have thousands of cases, so a big file is
read whole, and colcon (which trusts counts) and xunit-viewer (which reads elements)
must read the canonical file alike. Each stage has its own module: ``test_sanitiser``,
``test_markup``, ``test_safe_parser``, ``test_builder``; the entities a DOCTYPE
declares are read as a whole in ``test_reader_entities``.
"""

from __future__ import annotations

import os
import re
from collections import Counter
from pathlib import Path

from helpers import consumers
from helpers.xunit import many_cases, read_text
from lxml import etree

from ros_isolated_test.xunit import reader, validate
from ros_isolated_test.xunit.canonical import normalise_file

VIEWER_CASE = re.compile(r"^     ([✓✗!⊘?]) ", re.MULTILINE)
VIEWER_STATUS = {"✓": "passed", "✗": "failure", "!": "error", "⊘": "skipped", "?": "other"}
ONE_CASE = '<testsuite name="s"><testcase classname="C" name="a"/></testsuite>'


def counts(data: bytes) -> dict[str, str]:
    """The canonical suite's count attributes, after checking they match its cases."""
    root = etree.fromstring(data)
    assert validate.problems(root) == []
    suite = root.find("testsuite")
    assert suite is not None
    return {key: suite.get(key, "") for key in ("tests", "failures", "errors", "skipped")}


def colcon_counts(folder: Path) -> tuple[int, int, int, int]:
    """(tests, errors, failures, skipped): colcon's line for the one file under ``folder``."""
    proc = consumers.colcon_test_result(folder, folder)
    found = consumers.colcon_counts(proc.stdout)
    assert len(found) == 1, proc.stdout + proc.stderr
    [(tests, failures, errors, skipped)] = found.values()
    return tests, errors, failures, skipped


def viewer_counts(path: Path, cwd: Path) -> Counter[str]:
    """Each case's status as xunit-viewer's console shows it."""
    proc = consumers.run_xunit_viewer(path, cwd)
    return Counter(VIEWER_STATUS[mark] for mark in VIEWER_CASE.findall(proc.stdout))


# --- big files keep every case ---------------------------------------------------------------


def test_6000_cases_keep_every_case_and_every_reader_agrees(tmp_path: Path) -> None:
    source = tmp_path / "raw" / "big.xml"
    source.parent.mkdir()
    many_cases(source, 6000, {5100: "failure", 5999: "failure", 5500: "skipped"})
    data, failed = normalise_file(source, "pkg", "big")
    assert failed
    assert counts(data) == {"tests": "6000", "failures": "2", "errors": "0", "skipped": "1"}
    canonical = tmp_path / "canonical" / "big.xml"
    canonical.parent.mkdir()
    canonical.write_bytes(data)
    tree = etree.fromstring(data)
    failing = tree.xpath("//testcase[failure]/@name")
    assert failing == ["case5100", "case5999"]
    assert tree.xpath("//testcase[skipped]/@name") == ["case5500"]
    assert colcon_counts(canonical.parent) == (6000, 0, 2, 1)
    assert viewer_counts(canonical, tmp_path / "viewer") == Counter(
        {"passed": 5997, "failure": 2, "skipped": 1}
    )


# --- what is not a result file is said, never raised -------------------------------------


def test_an_empty_file_is_said_to_be_empty(tmp_path: Path) -> None:
    read = read_text(tmp_path, "")
    assert (read.problems, read.root_tag, read.size) == (["the result file is empty"], None, 0)
    control = read_text(tmp_path, ONE_CASE)
    assert (control.problems, control.root_tag) == ([], "testsuite")
    assert [case.attrs["name"] for case in control.cases] == ["a"]


def test_text_that_is_no_xml_is_said(tmp_path: Path) -> None:
    read = read_text(tmp_path, "this is not xml\n")
    assert read.problems == ["not XML (no element found in it)"]
    assert read.cases == []


def test_a_root_no_xunit_reader_takes_is_said(tmp_path: Path) -> None:
    """A ctest ``Test.xml`` is XML, but no result: ``report`` skips it by its root."""
    read = read_text(tmp_path, '<Site BuildName="Linux"><Testing/></Site>')
    assert read.problems == ["the root element is <Site>, not <testsuites> or <testsuite>"]
    assert (read.root_tag, read.is_xunit) == ("Site", False)
    assert read_text(tmp_path, ONE_CASE).is_xunit  # the control


def test_a_directory_a_fifo_or_nothing_at_the_path_is_said_without_hanging(
    tmp_path: Path,
) -> None:
    """A FIFO with no writer would block an ordinary open for ever: it is never read."""
    folder = tmp_path / "folder.xml"
    folder.mkdir()
    fifo = tmp_path / "fifo.xml"
    os.mkfifo(fifo)
    assert reader.read(folder).problems == ["a directory is where the result file should be"]
    assert reader.read(fifo).problems == [
        "something other than a file is where the result file should be"
    ]
    assert reader.read(tmp_path / "missing.xml").problems == [
        "cannot open the result file: No such file or directory"
    ]
    regular = tmp_path / "regular.xml"
    regular.write_text(ONE_CASE)
    assert reader.read(regular).problems == []  # the control


def test_a_second_root_is_ignored_and_said(tmp_path: Path) -> None:
    second = '<testsuite name="b"><testcase classname="C" name="y"/></testsuite>'
    read = read_text(tmp_path, ONE_CASE + second)
    assert read.problems == ["content after the root element (a second root?) was ignored"]
    assert [case.attrs["name"] for case in read.cases] == ["a"]


def test_a_cut_off_file_keeps_what_came_before_and_marks_the_case_it_ends_in(
    tmp_path: Path,
) -> None:
    text = '<testsuite name="s">\n<testcase name="x"/>\n<testcase name="y"><failure message="m">t'
    read = read_text(tmp_path, text)
    [problem] = read.problems
    assert problem.startswith("the file is cut off or broken at line 3 (")
    assert problem.endswith("); what came before is kept")
    assert [(case.attrs["name"], case.complete) for case in read.cases] == [
        ("x", True),
        ("y", False),
    ]
    assert read.cases[1].outcomes[0].text == "t"
    whole = read_text(tmp_path, text + "</failure></testcase></testsuite>")
    assert whole.problems == [] and all(case.complete for case in whole.cases)


def test_the_file_is_read_in_chunks_without_losing_a_case_at_a_boundary(tmp_path: Path) -> None:
    """Cases on both sides of every chunk boundary of a file over three chunks are all read."""
    source = tmp_path / "chunks.xml"
    count = 3 * reader.CHUNK_BYTES // 60
    many_cases(source, count, {})
    assert source.stat().st_size > 3 * reader.CHUNK_BYTES
    read = reader.read(source)
    assert (read.problems, read.size) == ([], source.stat().st_size)
    assert [case.attrs["name"] for case in read.cases] == [f"case{i}" for i in range(count)]
