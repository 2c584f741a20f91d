"""The reader keeps every failure of a big result file, and hostile markup costs bounded memory.

Big: real suites have thousands of cases, so every case is kept up to ``MAX_CASES``, and
beyond it every failed, errored and skipped case still is, by name; colcon (counts) and
xunit-viewer (elements) must read the canonical file alike. Hostile: lxml's parser holds
an attribute, a start tag, a comment or a CDATA section whole before it reports it, so
each is bounded in the byte stream, and the depth of open elements is capped; the files
are read in a child process whose peak RSS ``wait4`` reports.
"""

from __future__ import annotations

import itertools
import json
import re
import subprocess
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

import pytest
from helpers import peak_rss
from helpers.commands import BIN, REPO
from lxml import etree

from ros_isolated_test.text import shown_code
from ros_isolated_test.xunit import reader, validate, xml_text
from ros_isolated_test.xunit.result_file import normalise_file

MB = 1000 * 1000
HUGE = 200 * MB
#: Peak RSS a child reading a file with one 200 MB piece of markup may reach.
MAX_RSS = 150 * MB
CUT = re.compile(r"\[\.\.\. (\d+) characters cut \.\.\.\]")
XUNIT_VIEWER = REPO / "node_modules" / ".bin" / "xunit-viewer"
VIEWER_CASE = re.compile(r"^     ([✓✗!⊘?]) ", re.MULTILINE)
VIEWER_STATUS = {"✓": "passed", "✗": "failure", "!": "error", "⊘": "skipped", "?": "other"}
COLCON_LINE = re.compile(r"^(\S.*): (\d+) tests?, (\d+) errors?, (\d+) failures?, (\d+) skipped$")


def many_cases(path: Path, count: int, outcomes: dict[int, str]) -> None:
    """``count`` cases named ``case<i>``; ``outcomes`` maps an index to failure/error/skipped."""
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(f'<testsuites><testsuite name="s" tests="{count}">')
        for index in range(count):
            kind = outcomes.get(index)
            body = f'<{kind} message="{kind} {index}">trace {index}</{kind}>' if kind else ""
            handle.write(
                f'<testcase classname="C" name="case{index}" time="0.001">{body}</testcase>'
            )
        handle.write("</testsuite></testsuites>\n")


def counts(data: bytes) -> dict[str, str]:
    """The canonical suite's count attributes, after checking they match its cases."""
    root = etree.fromstring(data)
    assert validate.problems(root) == []
    suite = root.find("testsuite")
    assert suite is not None
    return {key: suite.get(key, "") for key in ("tests", "failures", "errors", "skipped")}


def colcon_counts(folder: Path) -> tuple[int, int, int, int]:
    proc = subprocess.run(
        [str(BIN / "colcon"), "test-result", "--test-result-base", str(folder), "--all"],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = [COLCON_LINE.match(line) for line in proc.stdout.splitlines()]
    found = [m.groups()[1:] for m in lines if m and not m.group(1).startswith("Summary")]
    assert len(found) == 1, proc.stdout + proc.stderr
    tests, errors, failures, skipped = (int(value) for value in found[0])
    return tests, errors, failures, skipped


def viewer_counts(path: Path, cwd: Path) -> Counter[str]:
    assert XUNIT_VIEWER.exists(), f"{XUNIT_VIEWER} is missing: scripts/setup.sh installs it"
    cwd.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(
        [str(XUNIT_VIEWER), "-r", str(path), "-c", "-o", "false", "--no-clear", "-n"],
        check=False,
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
    )
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    return Counter(VIEWER_STATUS[mark] for mark in VIEWER_CASE.findall(proc.stdout))


# --- big files keep every failure ---------------------------------------------------------


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
    count = reader.MAX_CASES + 5000
    scattered = {index: "failure" for index in range(reader.MAX_CASES + 7, count, 499)}
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
    kept = reader.MAX_CASES + sum(1 for index in scattered if index >= reader.MAX_CASES)
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


# --- hostile markup is bounded before the parser holds it ----------------------------------

_READ_IN_CHILD = """
import json, sys
from pathlib import Path
from ros_isolated_test.xunit import normalise, reader
read = reader.read(Path(sys.argv[1]))
cases = normalise.cases_from(read, None, "t")
print(json.dumps({
    "cases": [[c.name, c.outcome.value, c.message[:40], c.message[-40:], len(c.message),
               c.system_out[:20], c.system_out[-20:], "characters cut ...]" in c.message]
              for c in cases],
    "problems": read.problems,
    "repairs": read.repairs,
}))
"""


def child_rss(args: list[str], stdout: Path) -> int:
    """Run ``args`` with stdout into a file; its peak RSS in bytes, never charged with ours."""
    peak = peak_rss.measure(args, stdout=stdout)
    assert peak.returncode == 0 and not peak.timed_out, f"{args[:3]} failed"
    return peak.max_rss


def read_in_child(path: Path) -> tuple[dict[str, object], int]:
    """What a fresh interpreter reads from ``path``, and its peak RSS in bytes."""
    out = path.with_name("child.json")
    rss = child_rss([sys.executable, "-c", _READ_IN_CHILD, str(path)], out)
    return json.loads(out.read_text()), rss


Writer = Callable[[TextIO], None]


def _filler(handle: TextIO, char: str, size: int = HUGE) -> None:
    block = char * MB
    for _ in range(size // MB):
        handle.write(block)


def _message_attribute(handle: TextIO) -> None:
    handle.write('<testcase classname="C" name="a"><failure message="HEAD&amp;')
    _filler(handle, "m")
    handle.write('&lt;TAIL">trace</failure></testcase>')


def _name_attribute(handle: TextIO) -> None:
    handle.write('<testcase classname="C" name="HEAD')
    _filler(handle, "n")
    handle.write('TAIL"><failure message="m">trace</failure></testcase>')


def _tag_name(handle: TextIO) -> None:
    handle.write("<t")
    _filler(handle, "t")
    handle.write("/>")


def _attributes(handle: TextIO) -> None:
    handle.write('<testcase classname="C" name="a"')
    for start in range(0, 1_000_000, 100_000):
        handle.write("".join(f' x{index}="v"' for index in range(start, start + 100_000)))
    handle.write("/>")


def _comment(handle: TextIO) -> None:
    handle.write("<!--")
    _filler(handle, "c")
    handle.write('--><testcase classname="C" name="a"/>')


def _cdata(handle: TextIO) -> None:
    handle.write('<testcase classname="C" name="a"><system-out><![CDATA[HEAD')
    _filler(handle, "o")
    handle.write("TAIL]]></system-out></testcase>")


def _blanks_in_tag(handle: TextIO) -> None:
    handle.write('<testcase classname="C"')
    _filler(handle, " ")
    handle.write(' name="a"/>')


def _outcome_elements(handle: TextIO) -> None:
    handle.write('<testcase classname="C" name="a">')
    for _ in range(20):
        handle.write("<skipped/>" * 100_000)
    handle.write('<failure message="last"/></testcase>')


def _nested_elements(handle: TextIO) -> None:
    """20 million open elements (60 MB) after a whole case, inside a second one."""
    handle.write('<testcase classname="C" name="a"><failure message="before">t</failure>')
    handle.write('</testcase><testcase classname="C" name="deep"><system-out>')
    for _ in range(20):
        handle.write("<a>" * 1_000_000)


HOSTILE: dict[str, Writer] = {
    "200MB-message-attribute": _message_attribute,
    "200MB-name-attribute": _name_attribute,
    "200MB-tag-name": _tag_name,
    "a-million-attributes": _attributes,
    "200MB-comment": _comment,
    "200MB-cdata": _cdata,
    "200MB-of-blanks-in-a-tag": _blanks_in_tag,
    "2M-outcome-elements-in-one-case": _outcome_elements,
    "20M-nested-elements": _nested_elements,
}


def hostile_file(path: Path, write: Writer) -> None:
    with open(path, "w", encoding="utf-8") as handle:
        handle.write('<testsuites><testsuite name="s">')
        write(handle)
        handle.write('<testcase classname="C" name="b"/></testsuite></testsuites>')


@pytest.mark.parametrize("kind", sorted(HOSTILE))
def test_huge_markup_is_read_in_bounded_memory(tmp_path: Path, kind: str) -> None:
    source = tmp_path / "hostile.xml"
    hostile_file(source, HOSTILE[kind])
    try:
        summary, rss = read_in_child(source)
    finally:
        source.unlink()
    print(f"{kind}: peak RSS {rss / MB:.0f} MB")
    assert rss < MAX_RSS
    cases = summary["cases"]
    assert isinstance(cases, list)
    names = [case[0] for case in cases]
    if kind == "200MB-tag-name":
        assert summary["problems"] == [
            f"a name longer than {reader.MAX_NAME_CHARS} characters: not a result file"
        ]
        assert names == ["result file"]
        return
    if kind == "a-million-attributes":
        assert summary["problems"] == [
            f"{1_000_000 + 2 - reader.MAX_ATTRIBUTES} attribute(s) beyond the first "
            f"{reader.MAX_ATTRIBUTES} of an element were dropped"
        ]
        assert names == ["a", "b", "result file"]
        return
    if kind == "20M-nested-elements":
        assert summary["problems"] == [
            f"elements nest deeper than {reader.MAX_DEPTH} levels: not a result file; "
            "reading stopped there"
        ]
        # The case before is kept whole, the one the nesting is in as cut off.
        assert [case[:2] for case in cases[:2]] == [["a", "failure"], ["deep", "error"]]
        assert cases[0][2] == "before"
        assert cases[1][2].startswith("The result file ends inside this")
        assert names == ["a", "deep", "result file"]
        return
    assert summary["problems"] == []
    first = cases[0]
    if kind == "200MB-message-attribute":
        assert first[1:4] == ["failure", "HEAD&" + "m" * 35, "m" * 35 + "<TAIL"]
        assert first[4] < 2 * reader.ATTRIBUTE_LIMIT
        assert first[7], "the kept message is not marked as cut"
    elif kind == "200MB-name-attribute":
        assert first[0].startswith("HEAD") and first[0].endswith("TAIL")
        assert "characters cut ...]" in first[0]
        assert first[1] == "failure"
    elif kind == "200MB-cdata":
        # Not a character is lost in the parser: the text is cut only where texts are.
        assert first[5].startswith("HEAD") and first[6].endswith("TAIL")
    elif kind == "2M-outcome-elements-in-one-case":
        assert first[1:3] == ["failure", "last"]
        assert summary["repairs"] == [
            f"{2_000_000 - reader.MAX_OUTCOMES} failure, error or skipped element(s) beyond "
            f"{reader.MAX_OUTCOMES} in one test case were not kept"
        ]
    assert names[-1] == "b"


# --- character references: illegal ones shown, legal ones passed (most without a check) ------


def _references(codes: range | tuple[int, ...], form: str) -> list[tuple[str, int]]:
    return [(form.format(code), code) for code in codes]


def test_every_character_reference_is_shown_exactly_when_xml_forbids_it() -> None:
    """All code points, decimal and hex, some zero-padded: the fast path skips no bad one.

    In blocks: a test's peak memory is charged to every child pytest forks after it.
    """
    padded = (0, 8, 31, 32, 65, 9999, 10000, 49999, 50000, 0xD7FF, 0xD800, 0xFFFE)
    blocks = itertools.chain(
        (
            _references(range(first, min(first + 0x10000, 0x110002)), form)
            for first in range(0, 0x110002, 0x10000)
            for form in ("&#{};", "&#x{:x};")
        ),
        [_references(padded, "&#000{};") + _references(padded, "&#x00{:X};")],
    )
    for refs in blocks:  # one block at a time
        sanitiser = reader._Sanitiser(reader.ReadResult(Path("refs.xml")))
        body = "|".join(ref for ref, _code in refs)
        out = sanitiser.feed(f"<r>{body}</r>".encode(), final=True).decode()
        shown = out[len("<r>") : -len("</r>")].split("|")
        expected = [
            ref if xml_text.legal(code) and code != 0xFFFD else shown_code(code)
            for ref, code in refs
        ]
        assert shown == expected


# --- nesting: real files nest a handful of levels, a hostile one stops at the cap -------------

SAMPLES = Path(__file__).parent / "data" / "xunit"


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
    assert 4 <= _depth(path) <= 5 < reader.MAX_DEPTH // 100
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
    _nested(source, reader.MAX_DEPTH)
    read = reader.read(source)
    assert read.problems == []
    assert [case.attrs["name"] for case in read.cases] == ["a", "deep", "after"]
    assert read.cases[1].system_out == "x"
    assert read.cases[2].outcomes[0].tag == "failure"


def test_one_level_beyond_the_cap_stops_reading_and_keeps_what_came_before(
    tmp_path: Path,
) -> None:
    source = tmp_path / "deep.xml"
    _nested(source, reader.MAX_DEPTH + 1)
    read = reader.read(source)
    assert read.problems == [
        f"elements nest deeper than {reader.MAX_DEPTH} levels: not a result file; "
        "reading stopped there"
    ]
    assert [(case.attrs["name"], case.complete) for case in read.cases] == [
        ("a", True),
        ("deep", False),
    ]


def test_a_cut_attribute_value_is_marked_and_a_short_one_kept_whole(tmp_path: Path) -> None:
    """The cut keeps head and tail, whole references on both sides, and says how much went."""
    long = "&amp;" * 30_000 + "x" * 100_000 + "&lt;" * 30_000
    short = "&<" * 10 + "y" * 1000
    source = tmp_path / "cut.xml"
    source.write_text(
        f'<testsuites><testsuite name="s"><testcase classname="C" name="a">'
        f'<failure message="{long}">t</failure></testcase><testcase classname="C" name="b">'
        f'<failure message="{"&amp;&lt;" * 10 + "y" * 1000}">t</failure></testcase>'
        "</testsuite></testsuites>"
    )
    read = reader.read(source)
    assert read.problems == []
    cut = read.cases[0].outcomes[0].attrs["message"]
    head, marker, tail = cut.partition("\n[... ")
    assert marker
    assert set(head) == {"&"}
    assert set(tail.split("]\n", 1)[1]) == {"<"}
    match = CUT.search(cut)
    assert match is not None
    assert len(head) + int(match.group(1)) + len(tail.split("]\n", 1)[1]) > 200_000
    assert read.cases[1].outcomes[0].attrs["message"] == short


@pytest.mark.parametrize("size", [1, 5])
def test_cdata_over_many_sections_loses_nothing(tmp_path: Path, size: int) -> None:
    """A CDATA section is passed on in bounded sections, with ``]`` at every boundary."""
    body = ("]" * 3 + "x" * 1000 + "]]" + "y" * 997) * (size * 256)
    source = tmp_path / "cdata.xml"
    source.write_text(
        '<testsuites><testsuite name="s"><testcase classname="C" name="a">'
        f"<failure><![CDATA[{body}]]></failure></testcase></testsuite></testsuites>"
    )
    read = reader.read(source)
    assert read.problems == []
    text = read.cases[0].outcomes[0].text
    match = CUT.search(text)
    if match is None:
        assert text == body
    else:
        assert body.startswith(text[: match.start() - 1])
        assert body.endswith(text[match.end() + 1 :])
        assert int(match.group(1)) == len(body) - len(text) + len(match.group()) + 2


def test_control_peak_rss_of_a_big_child_is_seen(tmp_path: Path) -> None:
    """The RSS bound can fail: a child that touches 300 MB is measured as holding it."""
    touch = "b = bytearray(300 * 1000 * 1000)\nfor i in range(0, len(b), 4096): b[i] = 1"
    assert child_rss([sys.executable, "-c", touch], tmp_path / "out") > 300 * MB
