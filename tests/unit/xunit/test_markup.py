"""``xunit.markup``: huge markup bounded in the text stream, before the parser holds it whole.

lxml's parser holds an attribute value, a start tag, a comment or a CDATA section whole
before it reports it, so each is bounded in the text stream: an attribute value keeps
its head and tail around a marked cut, a CDATA section is passed on in sections (no
character lost), comments and processing instructions are dropped, a run of blanks in a
tag becomes one space, attributes beyond ``MAX_ATTRIBUTES`` are dropped and a name
beyond ``MAX_NAME_CHARS`` stops the reading. Hostile files are read whole in a child
process whose peak RSS ``wait4`` reports.
"""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

import pytest
from helpers.xunit import MB, child_rss
from lxml import etree

from ros_isolated_test.xunit import builder, markup, reader
from ros_isolated_test.xunit.markup import ATTRIBUTE_LIMIT, MAX_ATTRIBUTES, MAX_NAME_CHARS, Markup

HUGE = 200 * MB
#: Peak RSS a child reading a file with one 200 MB piece of markup may reach.
MAX_RSS = 150 * MB
CUT = re.compile(r"\[\.\.\. (\d+) characters cut \.\.\.\]")


def bounded(text: str) -> str:
    """``text`` through a fresh :class:`Markup` in one piece, failing on damage."""
    stream = Markup()
    out = stream.feed(text, final=True)
    assert stream.damage is None, stream.damage
    return out


# --- the stream, piece by piece -----------------------------------------------------------


def test_small_markup_passes_unchanged_however_it_is_cut() -> None:
    document = (
        '<testsuite name="s"><testcase classname="C" name="a" time="1">'
        '<failure message="x &amp; y" type="E">t &lt; u<![CDATA[ <raw> ]]></failure>'
        "</testcase><testcase name='b'/></testsuite>"
    )
    assert bounded(document) == document
    for size in (1, 2, 7):
        stream = Markup()
        pieces = [document[i : i + size] for i in range(0, len(document), size)]
        out = "".join(stream.feed(piece, final=False) for piece in pieces)
        assert out + stream.feed("", final=True) == document


def test_comments_and_processing_instructions_are_dropped() -> None:
    assert bounded("<a><!-- a comment --><?pi data?>text<!----></a>") == "<a>text</a>"


def test_a_huge_attribute_value_keeps_head_and_tail_around_a_marked_cut() -> None:
    value = "h" * ATTRIBUTE_LIMIT + "t" * ATTRIBUTE_LIMIT
    out = bounded(f'<a v="{value}" w="short"/>')
    kept = etree.fromstring(out).get("v")
    assert kept is not None
    half = ATTRIBUTE_LIMIT // 2
    assert kept.startswith("h" * half) and kept.endswith("t" * half)
    match = CUT.search(kept)
    assert match is not None and int(match.group(1)) == ATTRIBUTE_LIMIT
    assert len(kept) < ATTRIBUTE_LIMIT + 100
    assert etree.fromstring(out).get("w") == "short"
    whole = "v" * ATTRIBUTE_LIMIT  # the control: at the limit, nothing is cut
    assert etree.fromstring(bounded(f'<a v="{whole}"/>')).get("v") == whole


def test_attributes_beyond_the_limit_are_dropped_and_counted() -> None:
    stream = Markup()
    attributes = "".join(f' a{i}="{i}"' for i in range(MAX_ATTRIBUTES + 3))
    out = stream.feed(f"<e{attributes}/>", final=True)
    assert stream.dropped_attributes == 3
    assert len(etree.fromstring(out).attrib) == MAX_ATTRIBUTES
    control = Markup()
    control.feed(f"<e{attributes[: attributes.index(f' a{MAX_ATTRIBUTES}=')]}/>", final=True)
    assert control.dropped_attributes == 0


def test_a_name_longer_than_the_limit_stops_the_reading() -> None:
    assert bounded(f"<{'n' * MAX_NAME_CHARS}/>") == f"<{'n' * MAX_NAME_CHARS}/>"
    stream = Markup()
    stream.feed(f"<{'n' * (MAX_NAME_CHARS + 1)}/>", final=True)
    assert stream.damage == f"a name longer than {MAX_NAME_CHARS} characters: not a result file"


def test_a_long_run_of_blanks_in_a_tag_becomes_one_space() -> None:
    out = bounded(f'<a{" " * 10_000}b="1"{chr(10) * 100}/>')
    assert out == '<a b="1" />'
    assert bounded('<a  b="1"\n/>') == '<a  b="1"\n/>'  # the control: a short run is kept


# --- hostile files, read whole in bounded memory --------------------------------------------


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
            f"a name longer than {markup.MAX_NAME_CHARS} characters: not a result file"
        ]
        assert names == ["result file"]
        return
    if kind == "a-million-attributes":
        assert summary["problems"] == [
            f"{1_000_000 + 2 - markup.MAX_ATTRIBUTES} attribute(s) beyond the first "
            f"{markup.MAX_ATTRIBUTES} of an element were dropped"
        ]
        assert names == ["a", "b", "result file"]
        return
    if kind == "20M-nested-elements":
        assert summary["problems"] == [
            f"elements nest deeper than {builder.MAX_DEPTH} levels: not a result file; "
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
        assert first[4] < 2 * markup.ATTRIBUTE_LIMIT
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
            f"{2_000_000 - builder.MAX_OUTCOMES} failure, error or skipped element(s) beyond "
            f"{builder.MAX_OUTCOMES} in one test case were not kept"
        ]
    assert names[-1] == "b"


def test_control_peak_rss_of_a_big_child_is_seen(tmp_path: Path) -> None:
    """The RSS bound can fail: a child that touches 300 MB is measured as holding it."""
    touch = "b = bytearray(300 * 1000 * 1000)\nfor i in range(0, len(b), 4096): b[i] = 1"
    assert child_rss([sys.executable, "-c", touch], tmp_path / "out") > 300 * MB


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
