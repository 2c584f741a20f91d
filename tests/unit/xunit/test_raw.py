"""``xunit.raw``: what one result file says, as its producer wrote it, before normalising.

Records apart from the reading, so every reader of a result (``normalise``, ``report``,
``html_report``) names them without loading the reader and lxml behind it. Each record
starts empty and owns its lists; a case is complete until the reader says the file
ended inside it.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.xunit import modules_loaded

from ros_isolated_test.xunit.raw import RawCase, RawOutcome, RawSuite, ReadResult


@pytest.mark.parametrize(
    ("root", "xunit"),
    [
        ("testsuites", True),
        ("testsuite", True),
        ("Site", False),
        ("testcase", False),
        (None, False),
    ],
)
def test_only_testsuites_and_testsuite_roots_are_xunit(root: str | None, xunit: bool) -> None:
    assert ReadResult(Path("t.xml"), root_tag=root).is_xunit is xunit


def test_records_start_empty_and_never_share_their_lists() -> None:
    one, other = ReadResult(Path("a.xml")), ReadResult(Path("b.xml"))
    one.problems.append("broken")
    one.cases.append(RawCase({}, "s"))
    one.dropped["passed"] += 1
    assert (other.problems, other.cases, other.dropped, other.size) == ([], [], {}, 0)
    first, second = RawCase({}, "s"), RawCase({}, "s")
    first.outcomes.append(RawOutcome("failure", {}, "t"))
    assert second.outcomes == [] and second.complete
    suite, again = RawSuite("s", {}), RawSuite("s", {})
    suite.properties["exit_code"] = "1"
    assert again.properties == {}


def test_the_records_load_no_reader_and_no_lxml() -> None:
    names = ("lxml", "ros_isolated_test.xunit.reader")
    assert modules_loaded("import ros_isolated_test.xunit.raw", *names) == [False, False]
    # The control: importing the reader does load both.
    assert modules_loaded("import ros_isolated_test.xunit.reader", *names) == [True, True]
