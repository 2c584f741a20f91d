"""``xunit.builder``: each producer's elements turned into the raw model, with bounded memory.

The parser's target knows the shapes producers write (suites, cases and their
failure, error and skipped elements; gtest's and ctest's disabled tests; a suite's
properties; Surefire's rerun and flaky elements with an attempt's own output) and keeps
only what the normaliser reads. Its bounds are on what is kept: every case up to
``MAX_CASES`` and beyond it every case that did not pass, by name; elements nested to
``MAX_DEPTH``; what entities add to what the parser was given.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import cast

import pytest
from helpers.xunit import MB, SAMPLES, child_rss, many_cases
from lxml import etree

from ros_isolated_test.xunit import builder, raw, reader
from ros_isolated_test.xunit.builder import ENTITY_BUDGET, MAX_PROPERTIES, Builder, Stop


def built(*pieces: str | bytes, cut: bool = False) -> raw.ReadResult:
    """What the builder keeps of ``pieces``, fed in turn to a plain parser with it as target.

    ``cut``: the document ends inside an element, so closing the parser fails (as the
    reader's does at the end of a cut-off file), after it reported what it holds.
    """
    result = raw.ReadResult(Path("t.xml"))
    target = Builder(result)
    parser = etree.XMLParser(target=cast("etree.ParserTarget", target))
    for piece in pieces:
        parser.feed(piece.encode() if isinstance(piece, str) else piece)
    if cut:
        with pytest.raises(etree.XMLSyntaxError):
            parser.close()
    else:
        parser.close()
    target.finish()
    return result


# --- each producer's shapes -----------------------------------------------------------------


def test_a_case_keeps_its_outcomes_output_and_the_attributes_the_normaliser_reads() -> None:
    result = built(
        '<testsuites name="all" tests="1"><testsuite name="s" hostname="h">'
        '<testcase classname="C" name="a" time="0.5" file="t.py" line="3">'
        '<failure message="m" type="E" extra="x">trace</failure>'
        '<error message="e">boom</error><skipped/>'
        "<system-out>out</system-out><system-err>err</system-err></testcase>"
        "</testsuite></testsuites>"
    )
    assert (result.root_tag, result.root_attrs) == ("testsuites", {"name": "all", "tests": "1"})
    [suite] = result.suites
    assert (suite.name, suite.attrs) == ("s", {"name": "s", "hostname": "h"})
    [case] = result.cases
    assert case.attrs == {"classname": "C", "name": "a", "time": "0.5"}  # file, line: unread
    assert case.suite == "s" and case.complete
    assert [(item.tag, item.attrs, item.text) for item in case.outcomes] == [
        ("failure", {"message": "m", "type": "E"}, "trace"),
        ("error", {"message": "e"}, "boom"),
        ("skipped", {}, ""),
    ]
    assert (case.system_out, case.system_err) == ("out", "err")


def test_gtest_and_ctest_disabled_tests_keep_the_attributes_that_say_so() -> None:
    """A disabled test looks passed (no element says otherwise) but for these attributes.

    Real files, read by the whole reader: the builder is what keeps the attributes.
    """
    gtest = reader.read(SAMPLES / "gtest-1.17.0_mixed.gtest.xml")
    [disabled] = [case for case in gtest.cases if case.attrs["name"].startswith("DISABLED_")]
    assert (disabled.attrs["status"], disabled.attrs["result"]) == ("notrun", "suppressed")
    assert disabled.outcomes == []
    ctest = reader.read(SAMPLES / "ctest-4.4.4_output-junit.xml")
    by_name = {case.attrs["name"]: case for case in ctest.cases}
    assert by_name["disabled"].attrs["status"] == "disabled"
    assert by_name["pass"].attrs["status"] == "run"  # the control: a test that ran


def test_a_suites_properties_are_kept_and_a_cases_are_not() -> None:
    """ctest writes ``<properties/>`` in each case; only the suite's are the runner's record."""
    props = "".join(f'<property name="p{i}" value="{i}"/>' for i in range(MAX_PROPERTIES + 5))
    result = built(
        '<testsuite name="s"><property name="bare" value="not in properties"/>'
        '<testcase classname="C" name="a"><properties>'
        '<property name="in_case" value="x"/></properties></testcase>'
        '<properties><property name="exit_code" value="1"/>'
        '<property name="exit_code" value="2"/><property value="nameless"/>'
        f"{props}</properties></testsuite>"
    )
    properties = result.suites[0].properties
    assert properties["exit_code"] == "1"  # the first of a name is kept
    assert "in_case" not in properties and "bare" not in properties
    assert len(properties) == MAX_PROPERTIES
    assert [case.attrs["name"] for case in result.cases] == ["a"]
    assert result.cases[0].identity == ""


def test_of_a_cases_properties_only_its_identity_and_seconds_are_kept() -> None:
    """The pytest plugin names each item (``ros_isolated_test_identity``) for a split, and
    times it to the microsecond (``ros_isolated_test_seconds``)."""
    result = built(
        '<testsuite name="s"><testcase classname="C" name="a"><properties>'
        '<property name="other" value="x"/>'
        '<property name="ros_isolated_test_identity" value="pkg/test/t.py::a"/>'
        '<property name="ros_isolated_test_identity" value="pkg/second"/>'
        '<property name="ros_isolated_test_seconds" value="0.000317"/>'
        '<property name="ros_isolated_test_seconds" value="9"/>'
        '</properties></testcase><testcase classname="C" name="b"/></testsuite>'
    )
    assert [case.identity for case in result.cases] == ["pkg/test/t.py::a", ""]
    assert [case.seconds for case in result.cases] == ["0.000317", ""]
    assert result.suites[0].properties == {}


def test_surefire_attempts_keep_their_own_output_apart_from_their_text() -> None:
    result = built(
        '<testsuite name="s"><testcase classname="C" name="a">'
        '<flakyFailure message="first" type="E"><stackTrace>trace 1</stackTrace>'
        "<system-out>out 1</system-out><system-err>err 1</system-err></flakyFailure>"
        '<rerunError message="second" type="E">trace 2</rerunError>'
        "<system-out>the case's own</system-out></testcase></testsuite>"
    )
    [case] = result.cases
    assert [
        (item.tag, item.attrs["message"], item.text, item.system_out, item.system_err)
        for item in case.outcomes
    ] == [
        ("flakyFailure", "first", "trace 1", "out 1", "err 1"),
        ("rerunError", "second", "trace 2", "", ""),
    ]
    assert case.system_out == "the case's own"


def test_a_suites_own_output_and_nested_suites_name_their_cases() -> None:
    result = built(
        '<testsuites><testsuite name="outer"><testsuite name="inner">'
        '<testcase classname="C" name="a"/></testsuite><testcase classname="C" name="b"/>'
        "<system-out>outer's output</system-out></testsuite></testsuites>"
    )
    assert [(case.attrs["name"], case.suite) for case in result.cases] == [
        ("a", "inner"),
        ("b", "outer"),
    ]
    assert [(suite.name, suite.system_out) for suite in result.suites] == [
        ("outer", "outer's output"),
        ("inner", ""),
    ]


def test_a_case_the_file_ends_in_is_kept_marked_with_its_outcome_so_far() -> None:
    result = built(
        '<testsuite name="s"><testcase name="a"/><testcase name="b">',
        '<failure message="m">half a trace',
        cut=True,
    )
    assert [(case.attrs["name"], case.complete) for case in result.cases] == [
        ("a", True),
        ("b", False),
    ]
    assert [(item.tag, item.text) for item in result.cases[1].outcomes] == [
        ("failure", "half a trace")
    ]


# --- every failure of a big file is kept ---------------------------------------------------


_NORMALISE_IN_CHILD = """
import json, sys
from pathlib import Path
from lxml import etree
from ros_isolated_test.xunit import normalise, reader, validate
from ros_isolated_test.xunit.model import Suite
read = reader.read(Path(sys.argv[1]))
cases = normalise.cases_from(read, "pkg", "huge")
data = validate.render(Suite("pkg.huge", cases, 0.0, "2026-01-01T00:00:00", "h")).data
root = etree.fromstring(data)
suite = root.find("testsuite")
print(json.dumps({
    "problems": read.problems + validate.problems(root),
    "counts": {key: suite.get(key) for key in ("tests", "failures", "errors", "skipped")},
    "not_passed": {c.name: [c.outcome.value, c.message] for c in cases if c.outcome.rank},
    "last": [cases[-1].name, cases[-1].outcome.value, cases[-1].system_out],
    "size": len(data),
}))
"""


def test_beyond_the_bound_every_failure_is_kept_by_name(tmp_path: Path) -> None:
    """Past MAX_CASES only passed cases are summarised; every other one keeps its name.

    Read in a child: 105,000 cases cost this process memory that every later child it
    forks would be charged with (``ru_maxrss`` counts what a child inherits).
    """
    count = builder.MAX_CASES + 5000
    scattered = {index: "failure" for index in range(builder.MAX_CASES + 7, count, 499)}
    scattered[count - 3] = "error"
    scattered[count - 2] = "skipped"
    scattered[count - 1] = "failure"
    scattered[10] = "failure"  # one within the bound, for contrast
    source = tmp_path / "huge.xml"
    many_cases(source, count, scattered)
    out = tmp_path / "read.json"
    child_rss([sys.executable, "-c", _NORMALISE_IN_CHILD, str(source)], out)
    found = json.loads(out.read_text())
    assert found["problems"] == []
    failures = sum(1 for kind in scattered.values() if kind == "failure")
    kept = builder.MAX_CASES + sum(1 for index in scattered if index >= builder.MAX_CASES)
    assert found["counts"] == {
        "tests": str(kept + 1),
        "failures": str(failures),
        "errors": "1",
        "skipped": "1",
    }
    assert found["not_passed"] == {
        f"case{index}": [kind, f"{kind} {index}"] for index, kind in scattered.items()
    }
    passed_beyond = count - kept
    assert found["last"] == [
        "further test cases",
        "passed",
        f"{passed_beyond} further test case(s) were not kept, to keep the file small: "
        f"{passed_beyond} passed",
    ]
    assert found["size"] < 8 * MB


# --- nesting: real files nest a handful of levels, a hostile one stops at the cap -------------


def _depth(path: Path) -> int:
    depth = deepest = 0
    for event, _element in etree.iterparse(str(path), events=("start", "end")):
        depth += 1 if event == "start" else -1
        deepest = max(deepest, depth)
    return deepest


@pytest.mark.parametrize(
    "sample",
    ["pytest-9.2_xunit2.xml", "gtest-1.17.0_env_failure.xml", "ctest-4.4.4_output-junit.xml"],
)
def test_real_files_nest_a_handful_of_levels_and_are_read_whole(sample: str) -> None:
    """Control of the depth cap: testsuites/testsuite/testcase/failure files lose nothing."""
    path = SAMPLES / sample
    assert 4 <= _depth(path) <= 5 < builder.MAX_DEPTH // 100
    read = reader.read(path)
    assert read.problems == []
    names = etree.parse(str(path)).xpath("//testcase/@name")
    assert [case.attrs["name"] for case in read.cases] == names
    assert all(case.complete for case in read.cases)


def _nested(path: Path, depth: int) -> None:
    """A case ``deep`` whose output nests elements to ``depth`` levels in all, closed."""
    inner = depth - 4  # testsuites, testsuite, testcase, system-out
    path.write_text(
        '<testsuites><testsuite name="s"><testcase classname="C" name="a"/>'
        f'<testcase classname="C" name="deep"><system-out>{"<a>" * inner}x{"</a>" * inner}'
        '</system-out></testcase><testcase classname="C" name="after"><failure message="f"/>'
        "</testcase></testsuite></testsuites>"
    )


def test_elements_nested_to_the_cap_are_read(tmp_path: Path) -> None:
    source = tmp_path / "deep.xml"
    _nested(source, builder.MAX_DEPTH)
    read = reader.read(source)
    assert read.problems == []
    assert [case.attrs["name"] for case in read.cases] == ["a", "deep", "after"]
    assert read.cases[1].system_out == "x"
    assert read.cases[2].outcomes[0].tag == "failure"


def test_one_level_beyond_the_cap_stops_reading_and_keeps_what_came_before(
    tmp_path: Path,
) -> None:
    source = tmp_path / "deep.xml"
    _nested(source, builder.MAX_DEPTH + 1)
    read = reader.read(source)
    assert read.problems == [
        f"elements nest deeper than {builder.MAX_DEPTH} levels: not a result file; "
        "reading stopped there"
    ]
    assert [(case.attrs["name"], case.complete) for case in read.cases] == [
        ("a", True),
        ("deep", False),
    ]


# --- what entities add is counted, for a libxml2 that does not stop them ---------------------


def _builder(fed: int) -> Builder:
    builder = Builder(raw.ReadResult(Path("t.xml")))
    builder.fed, builder.count_expansion = fed, True  # as once a DOCTYPE reached the parser
    builder.start("testsuite", {"name": "s"})
    return builder


def test_the_readers_count_stops_what_an_old_libxml2_would_stream() -> None:
    """libxml2 before 2.11 streams an expansion to the target without bound, in time.

    The reader's builder counts what the parser reports against what it was fed; driven
    here as that parser would drive it.
    """
    builder = _builder(fed=1000)
    builder.data("B" * ENTITY_BUDGET)
    with pytest.raises(Stop, match=r"over 5 times what the file holds"):
        builder.data("B" * 1000)
    # Beyond the budget, five times what was fed is allowed.
    builder = _builder(fed=10 * ENTITY_BUDGET)
    builder.data("B" * 59 * ENTITY_BUDGET)
    with pytest.raises(Stop):
        builder.start("testcase", {"name": "B" * ENTITY_BUDGET})


def test_control_what_was_fed_is_never_too_much() -> None:
    builder = _builder(fed=100 * ENTITY_BUDGET)
    for _ in range(100):
        builder.data("B" * ENTITY_BUDGET)
    assert builder.reported == 100 * ENTITY_BUDGET + len("<testsuite>") + len("s")
