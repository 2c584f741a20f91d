"""Reading a result file written by arbitrary code: bounded, offline, and never giving up.

A test's result file may be broken or hostile: invalid UTF-8, characters XML forbids
(raw or as references), an entity bomb, a DTD that points at the network, two roots,
a cut-off end, gigabytes of output, a directory instead of a file. Everything is read
as a stream through a sanitiser into a strict parser whose events build a small raw
model; what cannot be read is described in ``problems`` and whatever came before it is
kept. Memory is bounded by the caps below, not by the file: markup the parser would hold
whole (an attribute, a tag, a comment, a CDATA section) is bounded before it gets there,
and so is the depth of open elements; texts and names shrink as they add up; every case
is kept up to MAX_CASES, and beyond it every case that did not pass.
"""

from __future__ import annotations

import codecs
import contextlib
import os
import re
import stat
import threading
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, cast

from lxml import etree

from ros_isolated_test.text import BoundedText, bounded, cut_mark, shown_code
from ros_isolated_test.xunit import xml_text
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT

#: Read at most this much of a file; the rest is reported, not parsed.
MAX_READ_BYTES = 256 * 1024 * 1024
CHUNK_BYTES = 1024 * 1024
#: Every test case is kept up to this many: no real suite has that many in one test.
MAX_CASES = 100_000
#: Beyond MAX_CASES, every failed, errored or skipped case is still kept, by name with a
#: short text, up to this many more (only a hostile file has more); passed cases beyond
#: MAX_CASES, and any beyond this, are counted in one summary case.
MAX_FURTHER_CASES = 10_000
#: Texts shrink as they add up, so the canonical file stays bounded however many cases
#: there are: TEXT_LIMIT characters each until all texts together reach TEXT_BUDGET,
#: SMALL_TEXT_LIMIT until twice that, TINY_TEXT_LIMIT after (and beyond MAX_CASES).
TEXT_BUDGET = 2 * 1024 * 1024
SMALL_TEXT_LIMIT = 200
TINY_TEXT_LIMIT = 40
#: Names likewise: NAME_LIMIT characters each until names reach NAME_BUDGET, then
#: SHORT_NAME_LIMIT (head and tail, so names still tell cases apart).
NAME_LIMIT = 256
NAME_BUDGET = 2 * 1024 * 1024
SHORT_NAME_LIMIT = 64
#: Failure, error and skipped elements kept per case (one of each kind always is), and
#: test suites whose own counts are kept: more only in a hostile file.
MAX_OUTCOMES = 16
MAX_SUITES = 10_000
#: Properties kept per suite: ours writes a few dozen.
MAX_PROPERTIES = 256
_PROPERTY_KEYS = frozenset({"name", "value"})
#: Elements nested deeper than this stop reading. Real producers nest four or five levels
#: (testsuites, testsuite, testcase, failure); the parser keeps a few words per open
#: element, so an unbounded depth costs memory in proportion to the file.
MAX_DEPTH = 1000
#: The attributes the normaliser reads; the others are not kept.
_CASE_KEYS = frozenset({"name", "classname", "time", "status", "result"})
_OUTCOME_KEYS = frozenset({"message", "type"})

_ATTEMPT_TAGS = frozenset({"rerunFailure", "rerunError", "flakyFailure", "flakyError"})
_IN_PROPERTIES = ["testsuite", "properties"]
OUTCOME_TAGS = frozenset({"failure", "error", "skipped"}) | _ATTEMPT_TAGS
#: A character reference, unless it is one of the many that are legal at a glance (32 to
#: 49999, 0x20 to 0xCFFF): those pass in C, not through a Python call each.
_CHAR_REF = re.compile(
    r"&#(?!0*(?:3[2-9]|[4-9][0-9]|[1-9][0-9]{2,3}|[1-4][0-9]{4});"
    r"|x0*(?:[2-9a-fA-F][0-9a-fA-F]|[1-9a-cA-C][0-9a-fA-F]{2,3});)"
    r"(?:x([0-9a-fA-F]{1,8})|([0-9]{1,10}));"
)
_OPEN_CHAR_REF = re.compile(r"&#x?[0-9a-fA-F]{0,10}$")
#: Markup that declares a DTD or entities after the prolog: made inert text.
_DTD_MARKUP = re.compile(r"<!(?=DOCTYPE|ENTITY|ELEMENT|ATTLIST|NOTATION)")
#: The first DOCTYPE reaches the parser, which expands its internal entities (see
#: :func:`new_parser`), when it ends within this many characters and the parser reads
#: it; otherwise it is dropped, and a file using its entities reads as damaged there.
DOCTYPE_LIMIT = 64 * 1024
#: What entities may add to the text and markup the parser reports: ENTITY_BUDGET
#: characters, and beyond that EXPANSION_FACTOR times what the parser was given. That
#: is libxml2's own bound since 2.11; older ones (Ubuntu 24.04's 2.9.14) stream an entity
#: bomb through a target parser in bounded memory, but for as long as it expands.
ENTITY_BUDGET = 1024 * 1024
EXPANSION_FACTOR = 5
#: Where the scan for a DOCTYPE's end stops: in its head, in its internal subset, in
#: one markup declaration.
_DOCTYPE_MARK = re.compile("[\"'\\[>]")
_SUBSET_MARK = re.compile("[\"'<\\]]")
_DECLARATION_MARK = re.compile("[\"'>]")
#: How libxml2 says it stopped expanding an entity: too far (2.11 and later), in a loop,
#: too deeply nested (2.11 and later; before, a loop too).
_ENTITY_BOMB = re.compile(
    r"entity amplification|entity reference loop|entity nesting depth", re.IGNORECASE
)
DOCTYPE_REMOVED = "a DOCTYPE was removed: no DTD or external entity is ever loaded"
_ENCODING = re.compile(rb"""^<\?xml[^>]*encoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")
_counts = threading.local()


def _count_and_show(error: UnicodeError) -> tuple[str, int]:
    r"""Show each undecodable byte as ``\xNN``, never as U+FFFD.

    A literal U+FFFD makes xunit-viewer guess the file is CP1252 and abort its run.
    """
    assert isinstance(error, UnicodeDecodeError)
    bad = error.object[error.start : error.end]
    _counts.invalid = getattr(_counts, "invalid", 0) + len(bad)
    return "".join(map(shown_code, bad)), error.end


codecs.register_error("ros_isolated_test.count", _count_and_show)


@dataclass(slots=True)
class RawOutcome:
    """A failure, error or skipped element as the producer wrote it.

    Surefire's rerun and flaky elements hold an attempt's own output as children.
    """

    tag: str
    attrs: dict[str, str]
    text: str
    system_out: str = ""
    system_err: str = ""


@dataclass(slots=True)
class RawCase:
    """A testcase element as the producer wrote it, texts already bounded."""

    attrs: dict[str, str]
    suite: str
    outcomes: list[RawOutcome] = field(default_factory=list)
    system_out: str = ""
    system_err: str = ""
    #: False when the file ended (or reading stopped) inside this case.
    complete: bool = True


@dataclass(slots=True)
class RawSuite:
    """A testsuite element: only what the normaliser uses."""

    name: str
    attrs: dict[str, str]
    system_out: str = ""
    system_err: str = ""
    #: Its ``<property>`` elements (the runner's record of how it ran the test: the
    #: report's timeline), the first MAX_PROPERTIES, values bounded like attributes.
    properties: dict[str, str] = field(default_factory=dict)


@dataclass
class ReadResult:
    """Everything that could be read from one result file, and what was wrong with it."""

    path: Path
    root_tag: str | None = None
    root_attrs: dict[str, str] = field(default_factory=dict)
    suites: list[RawSuite] = field(default_factory=list)
    cases: list[RawCase] = field(default_factory=list)
    #: Outcomes (``passed``, ``failure``, ...) of cases only counted (see MAX_CASES).
    dropped: Counter[str] = field(default_factory=Counter)
    #: What was wrong and damaged the content: reported as an error case.
    problems: list[str] = field(default_factory=list)
    #: What was wrong but repaired without loss of meaning: reported as a property.
    repairs: list[str] = field(default_factory=list)
    size: int = 0

    @property
    def is_xunit(self) -> bool:
        """Whether the root is one that xUnit readers accept."""
        return self.root_tag in ("testsuite", "testsuites")


#: Text pieces are gathered up to this many characters (or pieces) before they are cut.
_GATHER_CHARS = 64 * 1024
_GATHER_PIECES = 4096


class _Gathered:
    """A :class:`BoundedText` fed in batches.

    The parser reports the text around every entity or character reference as a piece
    of its own, and each ``BoundedText.add`` copies the kept tail: 30 million ``&amp;``
    took a minute one by one, seconds in batches.
    """

    def __init__(self, limit: int) -> None:
        self.text = BoundedText(limit)
        self.pieces: list[str] = []
        self.size = 0

    def add(self, piece: str) -> None:
        self.pieces.append(piece)
        self.size += len(piece)
        if self.size >= _GATHER_CHARS or len(self.pieces) >= _GATHER_PIECES:
            self._flush()

    def _flush(self) -> None:
        if self.pieces:
            self.text.add("".join(self.pieces))
            self.pieces, self.size = [], 0

    def value(self) -> str:
        self._flush()
        return self.text.value()


class _Budget:
    """How many characters a text or name may keep, shrinking as they add up."""

    def __init__(self) -> None:
        self.used = 0
        self.names = 0

    def limit(self, small: bool = False) -> int:
        if small or self.used >= 2 * TEXT_BUDGET:
            return TINY_TEXT_LIMIT
        return TEXT_LIMIT if self.used < TEXT_BUDGET else SMALL_TEXT_LIMIT

    def text(self, small: bool = False) -> _Gathered:
        return _Gathered(self.limit(small))

    def take(self, text: _Gathered) -> str:
        value = text.value()
        self.used += len(value)
        return value

    def attrs(
        self, attrib: object, keys: frozenset[str] | None = None, small: bool = False
    ) -> dict[str, str]:
        limit = self.limit(small)
        name_limit = NAME_LIMIT if self.names < NAME_BUDGET else SHORT_NAME_LIMIT
        result: dict[str, str] = {}
        for key, value in dict(attrib).items():  # type: ignore[call-overload]
            name = _local(str(key))
            if keys is not None and name not in keys:
                continue
            if name in ("name", "classname"):
                kept = bounded(str(value), name_limit)
                self.names += len(kept)
            else:
                kept = bounded(str(value), limit)
                self.used += len(kept)
            result[name] = kept
        return result


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


class _Stop(Exception):
    """Raised from a parser event, with the problem: lxml stops the parser and re-raises it."""


class _Builder:
    """Parser target: turns element events into the raw model, with bounded memory."""

    def __init__(self, result: ReadResult) -> None:
        self.result = result
        self.budget = _Budget()
        self.stack: list[str] = []
        self.suites: list[RawSuite] = []
        self.case: RawCase | None = None
        self.further = False  # the open case is beyond MAX_CASES
        self.kept_further = 0
        self.counting: str | None = None  # outcome of a case only counted
        self.in_counted_case = False
        self.text: _Gathered | None = None
        self.outcome_attrs: dict[str, str] = {}
        #: The output of an attempt inside a rerun or flaky element, apart from its text.
        self.attempt_output: _Gathered | None = None
        self.outcome_output: dict[str, str] = {}
        self.root_closed = False
        self.dropped_outcomes = 0
        self.dropped_suites = 0
        #: Characters given to the parser, and reported by it as names, attribute values
        #: and text: without entities never more than given. Counted only once a DOCTYPE
        #: reached the parser: without one, no entity can expand.
        self.fed = 0
        self.reported = 0
        self.count_expansion = False

    def _report(self, size: int) -> None:
        """Count what the parser reported; stop once entities added too much to it."""
        self.reported += size
        added = self.reported - self.fed
        if added > ENTITY_BUDGET and added > EXPANSION_FACTOR * self.fed:
            raise _Stop(
                f"entity references expand to over {EXPANSION_FACTOR} times what the file "
                "holds (an entity bomb?): reading stopped there"
            )

    def start(self, tag: str, attrib: object) -> None:
        if len(self.stack) >= MAX_DEPTH:
            raise _Stop(
                f"elements nest deeper than {MAX_DEPTH} levels: not a result file; "
                "reading stopped there"
            )
        name = _local(tag)
        if self.count_expansion:
            values = cast("dict[str, str]", attrib).values()
            self._report(len(name) + 2 + sum(map(len, values)))
        self.stack.append(name)
        if len(self.stack) == 1:
            self.result.root_attrs = self.budget.attrs(attrib)
            self.result.root_tag = name
        parent = self.stack[-2] if len(self.stack) > 1 else None
        if name == "testsuite":
            attrs = self.budget.attrs(attrib, small=len(self.result.suites) >= MAX_SUITES)
            suite = RawSuite(attrs.get("name", ""), attrs)
            self.suites.append(suite)
            if len(self.result.suites) < MAX_SUITES:
                self.result.suites.append(suite)
            else:
                self.dropped_suites += 1
        elif name == "property" and self.case is None and self.stack[-3:-1] == _IN_PROPERTIES:
            self._property(attrib)
        elif name == "testcase" and self.case is None and not self.in_counted_case:
            self._start_case(attrib)
        elif self.in_counted_case and parent == "testcase" and name in OUTCOME_TAGS:
            self.counting = _worse(self.counting or "passed", name)
        elif self.case is not None and parent == "testcase":
            if name in OUTCOME_TAGS:
                self._start_outcome(name, attrib)
            elif name in ("system-out", "system-err"):
                self.text = self.budget.text(self.further)
        elif self.case is not None and parent in _ATTEMPT_TAGS and self.text is not None:
            if name in ("system-out", "system-err"):
                self.attempt_output = self.budget.text(self.further)
        elif self.case is None and parent == "testsuite" and name in ("system-out", "system-err"):
            self.text = self.budget.text()

    def _property(self, attrib: object) -> None:
        properties = self.suites[-1].properties if self.suites else None
        if properties is None or len(properties) >= MAX_PROPERTIES:
            return
        attrs = self.budget.attrs(attrib, _PROPERTY_KEYS)
        if "name" in attrs:
            properties.setdefault(attrs["name"], attrs.get("value", ""))

    def _start_case(self, attrib: object) -> None:
        suite_name = self.suites[-1].name if self.suites else ""
        self.further = len(self.result.cases) >= MAX_CASES
        if self.further and self.kept_further >= MAX_FURTHER_CASES:
            self.in_counted_case = True
            self.counting = "passed"
            return
        self.case = RawCase(self.budget.attrs(attrib, _CASE_KEYS, self.further), suite_name)

    def _start_outcome(self, name: str, attrib: object) -> None:
        assert self.case is not None
        outcomes = self.case.outcomes
        if len(outcomes) >= MAX_OUTCOMES and any(item.tag == name for item in outcomes):
            self.dropped_outcomes += 1
            return
        self.outcome_attrs = self.budget.attrs(attrib, _OUTCOME_KEYS, self.further)
        self.outcome_output = {}
        self.text = self.budget.text(self.further)

    def data(self, data: str | bytes) -> None:
        if self.count_expansion:
            self._report(len(data))
        target = self.attempt_output or self.text
        if target is not None:
            target.add(data if isinstance(data, str) else data.decode("utf-8", "replace"))

    def end(self, tag: str) -> None:
        name = _local(tag)
        if self.stack:
            self.stack.pop()
        parent = self.stack[-1] if self.stack else None
        if self.attempt_output is not None and name in ("system-out", "system-err"):
            self.outcome_output[name] = self.budget.take(self.attempt_output)
            self.attempt_output = None
            return
        if name == "testcase" and self.in_counted_case and parent != "testcase":
            self.result.dropped[self.counting or "passed"] += 1
            self.in_counted_case = False
            self.counting = None
        elif name == "testcase" and self.case is not None and parent != "testcase":
            self._end_case(self.case)
            self.case = None
        elif self.text is not None and parent == "testcase" and self.case is not None:
            value = self.budget.take(self.text)
            if name in OUTCOME_TAGS:
                output = self.outcome_output
                self.case.outcomes.append(
                    RawOutcome(
                        name,
                        self.outcome_attrs,
                        value,
                        output.get("system-out", ""),
                        output.get("system-err", ""),
                    )
                )
            elif name == "system-out":
                self.case.system_out = value
            elif name == "system-err":
                self.case.system_err = value
        elif self.text is not None and parent == "testsuite" and self.suites:
            value = self.budget.take(self.text)
            if name == "system-out":
                self.suites[-1].system_out = value
            else:
                self.suites[-1].system_err = value
        if name in OUTCOME_TAGS or name in ("system-out", "system-err"):
            self.text = None
        if name == "testsuite" and self.suites:
            self.suites.pop()
        if not self.stack:
            self.root_closed = True

    def _end_case(self, case: RawCase) -> None:
        """Keep the case; beyond MAX_CASES only if it did not pass (passed ones are counted)."""
        if self.further and not _noteworthy(case):
            self.result.dropped["passed"] += 1
            return
        self.kept_further += self.further
        self.result.cases.append(case)

    def comment(self, text: str | bytes) -> None:
        return None

    def close(self) -> None:
        return None

    def finish(self) -> None:
        """Say what a hostile file lost; keep a case the file ended inside, marked."""
        if self.case is not None:
            if self.text is not None and self.stack and self.stack[-1] in OUTCOME_TAGS:
                value = self.budget.take(self.text)
                self.case.outcomes.append(RawOutcome(self.stack[-1], self.outcome_attrs, value))
            self.case.complete = False
            self.result.cases.append(self.case)
            self.case = None
        if self.dropped_outcomes:
            self.result.repairs.append(
                f"{self.dropped_outcomes} failure, error or skipped element(s) beyond "
                f"{MAX_OUTCOMES} in one test case were not kept"
            )
        if self.dropped_suites:
            self.result.repairs.append(
                f"the own counts of {self.dropped_suites} test suite(s) beyond the first "
                f"{MAX_SUITES} were not checked"
            )


def _noteworthy(case: RawCase) -> bool:
    """Whether a case failed, errored, was skipped or was cut off: kept by name always."""
    disabled = case.attrs.get("status") == "disabled" or case.attrs.get("result") == "suppressed"
    primary = any(item.tag in ("failure", "error", "skipped") for item in case.outcomes)
    return disabled or primary or not case.complete


_RANK = {"passed": 0, "skipped": 1, "error": 2, "failure": 3}


def _worse(current: str, tag: str) -> str:
    kind = "failure" if "Failure" in tag or tag == "failure" else tag
    kind = "error" if "Error" in tag else kind
    return kind if _RANK.get(kind, 0) > _RANK.get(current, 0) else current


#: Markup the parser holds whole before it reports it, bounded in the byte stream: an
#: attribute value keeps its head and tail around a marked cut, a CDATA section is cut
#: into sections of this size (no character lost), comments and processing
#: instructions are dropped, a run of blanks inside a tag becomes one space.
ATTRIBUTE_LIMIT = TEXT_LIMIT
CDATA_SECTION = 256 * 1024
#: An element with more attributes than this loses the rest; a longer name stops reading.
MAX_ATTRIBUTES = 256
MAX_NAME_CHARS = 1024
_BLANKS = re.compile(r"[ \t\r\n]*")
_NAME_CHARS = re.compile(r"[^ \t\r\n=/<>\"'&]*")
_NOT_NAME = frozenset(" \t\r\n=/<>\"'&")
_TAG_NAME = r"[^ \t\r\n=/<>\"'&!?][^ \t\r\n=/<>\"'&]{0,255}"
_PLAIN_ATTRIBUTE = (
    r"[ \t\r\n]{1,64}[^ \t\r\n=/<>\"'&]{1,256}[ \t\r\n]{0,64}=[ \t\r\n]{0,64}"
    r"(?:\"[^\"<]{0,4096}\"|'[^'<]{0,4096}')"
)
#: Text and small, complete tags: passed on in C-speed matches, so only the rare large
#: or unfinished piece of markup costs Python steps. Each match takes at most _PLAIN_RUN
#: pieces: ``re`` keeps a backtracking record per piece, 400 bytes, and a megabyte of
#: ``<a>`` is 333,333 pieces.
_PLAIN_RUN = 1000
_PLAIN = re.compile(
    rf"(?:[^<]+|<{_TAG_NAME}(?:{_PLAIN_ATTRIBUTE}){{0,64}}[ \t\r\n]{{0,64}}/?>"
    rf"|</{_TAG_NAME}[ \t\r\n]{{0,64}}>){{0,{_PLAIN_RUN}}}"
)
_REFERENCE_TAIL = re.compile(r"^[#0-9A-Za-z]{0,10};")
_OPEN_REFERENCE = re.compile(r"&[#0-9A-Za-z]{0,10}$")
(_TEXT, _COMMENT, _CDATA, _PI, _NAME, _TAG, _ATTR_NAME, _EQUALS, _VALUE) = range(9)


class _ValueCut:
    """An attribute value streamed through: the head passes, the tail is held, the middle cut."""

    def __init__(self, limit: int) -> None:
        self.room = limit // 2
        self.tail = ""
        self.keep = limit // 2
        self.cut = 0

    def add(self, piece: str, out: list[str]) -> None:
        if self.room > 0:
            head = piece[: self.room]
            self.room -= len(head)
            piece = piece[len(head) :]
            if self.room == 0 and (open_ref := _OPEN_REFERENCE.search(head)):
                # Never cut inside a reference: it goes to the tail side instead.
                piece = head[open_ref.start() :] + piece
                head = head[: open_ref.start()]
                self.room = 0
            out.append(head)
        if piece:
            joined = self.tail + piece
            self.cut += max(len(joined) - self.keep, 0)
            self.tail = joined[-self.keep :]

    def finish(self, out: list[str]) -> None:
        tail = self.tail
        if self.cut:
            partial = _REFERENCE_TAIL.match(tail)
            if partial:
                self.cut += partial.end()
                tail = tail[partial.end() :]
            out.append(cut_mark(self.cut).replace("\n", "&#10;"))
        out.append(tail)


class _Markup:
    """Keeps the parser from holding any one piece of markup whole when it is huge.

    lxml's parser gets a start tag, an attribute value, a comment, a processing
    instruction or a CDATA section whole before it says anything about it: one 200 MB
    attribute cost 600 MB. This sees the sanitised text as markup, streaming, and
    bounds each of them before the parser buffers it, keeping the document well-formed
    (or broken exactly where it was). Damage it cannot repair stops the reading.
    """

    def __init__(self) -> None:
        self.state = _TEXT
        self.pending = ""
        self.name_chars = 0
        self.attributes = 0
        self.keep_attribute = True
        self.quote = ""
        self.value: _ValueCut | None = None
        self.section = 0
        self.dropped_attributes = 0
        self.damage: str | None = None

    def feed(self, text: str, final: bool) -> str:
        """The next sanitised piece, bounded; ``final`` flushes what was held back."""
        text, self.pending = self.pending + text, ""
        out: list[str] = []
        pos, end = 0, len(text)
        steps = {
            _TEXT: self._text,
            _COMMENT: self._skipped,
            _PI: self._skipped,
            _CDATA: self._cdata,
            _NAME: self._name,
            _ATTR_NAME: self._name,
            _VALUE: self._value,
        }
        while pos < end and self.damage is None:
            pos = steps.get(self.state, self._in_tag)(text, pos, final, out)
        if final:
            if self.value is not None and self.keep_attribute:
                self.value.finish(out)
            out.append(self.pending)
            self.pending = ""
        return "".join(out)

    def _hold(self, text: str, start: int) -> int:
        """Keep ``text[start:]`` for the next piece, which decides what it is."""
        self.pending = text[start:]
        return len(text)

    def _text(self, text: str, pos: int, final: bool, out: list[str]) -> int:
        start = -1
        while pos > start:
            start = pos
            plain = _PLAIN.match(text, start)
            assert plain is not None
            out.append(plain.group())
            pos = plain.end()
        if start >= len(text):
            return start
        ahead = text[start : start + 9]
        if not final and len(ahead) < 9:
            return self._hold(text, start)
        if ahead.startswith("<!--"):
            self.state = _COMMENT
            return start + 4
        if ahead.startswith("<![CDATA["):
            out.append("<![CDATA[")
            self.state, self.section = _CDATA, 0
            return start + 9
        if ahead.startswith("<?"):
            self.state = _PI
            return start + 2
        self.state, self.name_chars, self.keep_attribute = _NAME, 0, True
        if ahead.startswith("</"):
            out.append("</")
            return start + 2
        out.append("<")
        self.attributes = 0
        return start + 1

    def _skipped(self, text: str, pos: int, final: bool, out: list[str]) -> int:
        """Comments and processing instructions: nothing a result needs, dropped."""
        close = "-->" if self.state == _COMMENT else "?>"
        found = text.find(close, pos)
        if found < 0:
            return self._hold(text, max(len(text) - len(close) + 1, pos))
        self.state = _TEXT
        return found + len(close)

    def _cdata(self, text: str, pos: int, final: bool, out: list[str]) -> int:
        found = text.find("]]>", pos)
        stop = found if found >= 0 else max(len(text) - 2, pos)
        out.append(text[pos:stop])
        self.section += stop - pos
        if found >= 0:
            out.append("]]>")
            self.state = _TEXT
            return found + 3
        if self.section >= CDATA_SECTION:
            # End the section and open another: the same text, in bounded pieces.
            out.append("]]><![CDATA[")
            self.section = 0
        return self._hold(text, stop)

    def _name(self, text: str, pos: int, final: bool, out: list[str]) -> int:
        match = _NAME_CHARS.match(text, pos)
        assert match is not None
        self.name_chars += match.end() - pos
        if self.name_chars > MAX_NAME_CHARS:
            self.damage = f"a name longer than {MAX_NAME_CHARS} characters: not a result file"
            return len(text)
        if self.keep_attribute:
            out.append(match.group())
        if match.end() < len(text):
            self.state = _TAG if self.state == _NAME else _EQUALS
        return match.end()

    def _value(self, text: str, pos: int, final: bool, out: list[str]) -> int:
        assert self.value is not None
        found = text.find(self.quote, pos)
        stop = found if found >= 0 else len(text)
        if self.keep_attribute:
            self.value.add(text[pos:stop], out)
        if found < 0:
            return stop
        if self.keep_attribute:
            self.value.finish(out)
            out.append(self.quote)
        self.state, self.value = _TAG, None
        return found + 1

    def _in_tag(self, text: str, pos: int, final: bool, out: list[str]) -> int:
        """Blanks, ``=``, a quote, a name, ``/`` or ``>`` inside a start or end tag."""
        blanks = _BLANKS.match(text, pos)
        assert blanks is not None
        if blanks.end() > pos:
            run = blanks.group()
            out.append(run if len(run) <= 64 else " ")
            return blanks.end()
        char = text[pos]
        if self.state == _EQUALS and char == "=":
            self.state = _TAG
            if self.keep_attribute:
                out.append(char)
            return pos + 1
        if char in "\"'":
            self.state, self.quote, self.value = _VALUE, char, _ValueCut(ATTRIBUTE_LIMIT)
            if self.keep_attribute:
                out.append(char)
            return pos + 1
        if char == "/" and pos + 1 == len(text):
            self.pending = char  # is it "/>"? The next piece says.
            return pos + 1
        if char in _NOT_NAME:
            # ">", "/>", or a character no tag may hold: then the tag is closed right
            # after it, so the parser reports it now instead of buffering until a ">".
            self.state, self.keep_attribute = _TEXT, True
            closing = text[pos : pos + 2] if text.startswith("/>", pos) else char
            out.append(closing if closing in (">", "/>") else f"{closing}>")
            return pos + len(closing)
        self.attributes += 1
        self.keep_attribute = self.attributes <= MAX_ATTRIBUTES
        self.dropped_attributes += not self.keep_attribute
        self.state, self.name_chars = _ATTR_NAME, 0
        return pos


def _doctype_end(text: str) -> int:
    """Past the ``>`` that ends the DOCTYPE ``text`` starts with; -1 if it ends later.

    Only its extent is looked for, so the parser gets the DOCTYPE whole and nothing of the
    prolog around it: quoted literals, comments and processing instructions are skipped
    whole, and what the declarations say is the parser's to read.
    """
    pos, marks = len("<!DOCTYPE"), _DOCTYPE_MARK
    while pos >= 0 and (mark := marks.search(text, pos)):
        char, pos = mark.group(), mark.end()
        if char == ">":
            return pos
        if char in "\"'":
            pos = _after(text, char, pos)
        elif char in "[]":
            marks = _SUBSET_MARK if char == "[" else _DOCTYPE_MARK
        elif text.startswith("!--", pos):
            pos = _after(text, "-->", pos + 3)
        elif text.startswith("?", pos):
            pos = _after(text, "?>", pos + 1)
        else:
            pos = _declaration_end(text, pos)
    return -1


def _declaration_end(text: str, pos: int) -> int:
    """Past the ``>`` closing the markup declaration ``pos`` is in (quotes skipped); -1."""
    while mark := _DECLARATION_MARK.search(text, pos):
        if mark.group() == ">":
            return mark.end()
        pos = _after(text, mark.group(), mark.end())
        if pos < 0:
            return -1
    return -1


def _after(text: str, end: str, pos: int) -> int:
    """Past the next ``end`` from ``pos``; -1 if there is none."""
    found = text.find(end, pos)
    return found + len(end) if found >= 0 else -1


_NOT_XML = frozenset({"idna", "punycode", "undefined", "raw_unicode_escape", "unicode_escape"})


class _Sanitiser:
    """Bytes in, clean UTF-8 out: decoded, illegal characters shown, the prolog defused."""

    def __init__(self, result: ReadResult) -> None:
        self.result = result
        self.decoder: codecs.IncrementalDecoder | None = None
        self.carry = ""
        self.in_prolog = True
        self.in_comment = False
        self.doctype_seen = False
        #: The DOCTYPE's text while it is gathered, up to DOCTYPE_LIMIT characters.
        self.doctype: str | None = None
        #: What goes to the parser before the root element: line breaks and the DOCTYPE.
        self.head = ""
        self.doctype_kept = False
        self.prolog_lines = 0
        self.illegal = 0
        self.markup = _Markup()

    def feed(self, data: bytes, final: bool = False) -> bytes:
        text = self.carry + self._decode(data, final)
        self.carry = ""
        if not final:
            # Keep back a reference, colour code or DTD keyword cut by the chunk boundary.
            tail = text[-80:]
            held = [m.start() for m in (_OPEN_CHAR_REF.search(tail),) if m is not None]
            held += [tail.rfind(mark) for mark in ("\x1b", "<") if mark in tail]
            if held:
                cut = len(text) - len(tail) + min(held)
                text, self.carry = text[:cut], text[cut:]
        if "\x1b" in text:
            text = xml_text.ansi_escape().sub("", text)
        shown = text.translate(xml_text.CONTROL_TABLE)
        # Each control character shown grows by 3 (\x01 for one character).
        self.illegal += (len(shown) - len(text)) // 3
        text = shown
        if not text.isascii() and xml_text.rare_illegal().search(text):
            text = xml_text.rare_illegal().sub(self._show, text)
        if "&#" in text:
            text = _CHAR_REF.sub(self._show_reference, text)
        head = ""
        if self.in_prolog:
            text, unfinished = self._skip_prolog(text, final)
            self.carry = unfinished + self.carry
            if not self.in_prolog:
                head, self.head = self.head, ""
        if "<!" in text:
            # Anything DTD-like after the prolog (smuggled, late) is made inert: the
            # parser then reports broken markup instead of defining entities.
            text, found = _DTD_MARKUP.subn("&lt;!", text)
            if found:
                self.result.repairs.append(
                    "DTD markup after the root element started was made inert: it declares "
                    "nothing and loads nothing"
                )
        return (head + self.markup.feed(text, final)).encode("utf-8")

    def _decode(self, data: bytes, final: bool) -> str:
        if self.decoder is None:
            self.decoder = codecs.getincrementaldecoder(self._encoding(data))(
                "ros_isolated_test.count"
            )
        try:
            return self.decoder.decode(data, final)
        except (UnicodeError, LookupError, TypeError, ValueError):
            # A codec that is no text encoding after all: read the rest as UTF-8.
            self.result.repairs.append("the declared encoding failed; read as UTF-8")
            self.decoder = codecs.getincrementaldecoder("utf-8")("ros_isolated_test.count")
            return self.decoder.decode(data, final)

    def _encoding(self, head: bytes) -> str:
        if head.startswith(codecs.BOM_UTF8):
            return "utf-8-sig"
        if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
            return "utf-16"
        match = _ENCODING.match(head[:512])
        if match:
            name = match.group(1).decode("ascii", "replace")
            with contextlib.suppress(LookupError):
                info = codecs.lookup(name)
                # hex, base64, rot13 and the like are codecs, not text encodings.
                if getattr(info, "_is_text_encoding", True) and info.name not in _NOT_XML:
                    return info.name
            self.result.repairs.append(f"unknown encoding {name!r} declared; read as UTF-8")
        return "utf-8"

    def _show(self, match: re.Match[str]) -> str:
        self.illegal += 1
        return shown_code(ord(match.group()))

    def _show_reference(self, match: re.Match[str]) -> str:
        code = int(match.group(1), 16) if match.group(1) else int(match.group(2))
        if xml_text.legal(code) and code != 0xFFFD:
            return match.group()
        self.illegal += 1
        return shown_code(code)

    def _skip_prolog(self, text: str, final: bool = False) -> tuple[str, str]:
        """Drop everything before the root element but the DOCTYPE, streaming.

        The prolog may only hold the declaration (we re-encode anyway), comments,
        processing instructions and a DOCTYPE. The first DOCTYPE is gathered whole and
        put in ``head``, for the parser to expand its internal entities (it loads
        nothing external, see :func:`new_parser`); the rest is not needed. Returns the
        text from the root element on, and an unfinished tail to look at again.
        """
        index = 0
        while True:
            if self.doctype is not None:
                whole = self.doctype + text[index:]
                end = _doctype_end(whole[:DOCTYPE_LIMIT])
                if end < 0 and len(whole) <= DOCTYPE_LIMIT and not final:
                    self.doctype = whole
                    return "", ""  # it ends in a later chunk
                self.doctype = None
                if end < 0:
                    # Too long or never ended: scanned on as prolog, from inside it.
                    self.result.repairs.append(
                        f"the DOCTYPE does not end within {DOCTYPE_LIMIT} characters: "
                        "its entities are not defined"
                    )
                    text, index = whole, len("<!DOCTYPE")
                else:
                    self._keep_doctype(whole[:end])
                    text, index = whole[end:], 0
                continue
            if self.in_comment:
                end = text.find("-->", index)
                if end < 0:
                    self.prolog_lines += text.count("\n", 0, len(text) - 2)
                    return "", text[-2:]
                index, self.in_comment = end + 3, False
                continue
            start = text.find("<", index)
            if start < 0 or start + 1 >= len(text):
                kept = len(text) if start < 0 else start
                self.prolog_lines += text.count("\n", 0, kept)
                return "", text[kept:]
            if len(text) - start < 9 and "<!DOCTYPE".startswith(text[start:]):
                self.prolog_lines += text.count("\n", 0, start)
                return "", text[start:]  # a keyword cut by the chunk boundary
            if text.startswith("<!--", start):
                self.in_comment, index = True, start + 4
                continue
            if text.startswith("<!DOCTYPE", start) and not self.doctype_seen:
                self.doctype_seen = True
                self.result.repairs.append(DOCTYPE_REMOVED)
                self.prolog_lines += text.count("\n", 0, start)
                self.doctype, text, index = "", text[start:], 0
                continue
            after = text[start + 1]
            if after.isalpha() or after in "_:":
                self.in_prolog = False
                # Keep the line count, so the parser's line numbers match the file's.
                self.head += "\n" * min(self.prolog_lines + text.count("\n", 0, start), 100_000)
                return text[start:], ""
            index = start + 1

    def _keep_doctype(self, doctype: str) -> None:
        """Put ``doctype`` in ``head`` if the parser reads it; else drop it, saying why.

        A broken DOCTYPE would make the whole file unreadable; without it, only a use of
        its entities is damage.
        """
        try:
            etree.fromstring(f"{doctype}<x/>".encode(), new_parser())
        except etree.XMLSyntaxError as error:
            self.prolog_lines += doctype.count("\n")
            self.result.repairs.append(
                f"a DOCTYPE the parser cannot read ({_message(error)}) was dropped: "
                "its entities are not defined"
            )
            return
        self.head = "\n" * min(self.prolog_lines, 100_000) + doctype
        self.prolog_lines = 0
        self.doctype_kept = True

    def finish(self) -> None:
        if self.markup.dropped_attributes:
            self.result.problems.append(
                f"{self.markup.dropped_attributes} attribute(s) beyond the first "
                f"{MAX_ATTRIBUTES} of an element were dropped"
            )
        invalid = getattr(_counts, "invalid", 0)
        if invalid:
            self.result.repairs.append(
                f"{invalid} byte(s) that were not valid text were written as \\xNN"
            )
        if self.illegal:
            self.result.repairs.append(
                f"{self.illegal} character(s) that XML 1.0 forbids were written as \\xNN"
            )


def _open_regular(path: Path, result: ReadResult) -> BinaryIO | None:
    """The file opened for reading, or None with the reason added to ``result``."""
    try:
        # Raises for a file in a folder this user may list but not enter.
        is_dir = path.is_dir()
    except OSError as error:
        result.problems.append(f"cannot open the result file: {error.strerror}")
        return None
    if is_dir:
        result.problems.append("a directory is where the result file should be")
        return None
    try:
        # Non-blocking: a FIFO planted at the path must not hang the runner.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as error:
        result.problems.append(f"cannot open the result file: {error.strerror}")
        return None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        result.problems.append("something other than a file is where the result file should be")
        return None
    os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


def read(path: Path) -> ReadResult:
    """Read ``path`` as far as it can be read; never raises for what the file contains."""
    result = ReadResult(path=path)
    handle = _open_regular(path, result)
    if handle is None:
        return result
    with handle:
        _parse(handle, result)
    if result.size == 0:
        result.problems[:] = ["the result file is empty"]
    elif result.root_tag is None and not result.problems:
        result.problems.append("no XML element was found in the result file")
    elif result.root_tag is not None and not result.is_xunit:
        result.problems.append(
            f"the root element is <{result.root_tag}>, not <testsuites> or <testsuite>"
        )
    return result


class _NothingExternal(etree.Resolver):
    """Answers every DTD, entity or file the parser would load with nothing.

    ``resolve_entities='internal'`` refuses external general entities only: libxml2
    before 2.13 still loads an external parameter entity (``%p;``) from a file here
    (lxml 5.2.1's bundled 2.12 does, and so does Ubuntu 24.04's 2.9.14).
    """

    def resolve(  # type: ignore[override]  # lxml passes a context; its stubs omit it
        self, system_url: str, public_id: str, context: object
    ) -> object:
        return self.resolve_string("", context, base_url=None)


def new_parser(target: object | None = None) -> etree.XMLParser:
    """The parser every result file is read with: safe on its own, whatever it is fed.

    libxml2 expands a DOCTYPE's internal entities and nothing else: no DTD, external
    entity or URL is loaded, and without ``huge_tree`` it keeps its limits on entity
    expansion (2.11 and later) and on one text, name or attribute value. It does not
    bound one huge attribute, CDATA section or comment in memory: the sanitiser does.
    """
    parser = etree.XMLParser(
        target=cast("etree.ParserTarget | None", target),
        resolve_entities="internal",  # type: ignore[arg-type]  # lxml-stubs predate lxml 5
        load_dtd=False,
        no_network=True,
        huge_tree=False,
        remove_pis=True,
    )
    parser.resolvers.add(_NothingExternal())
    return parser


def _parse(handle: BinaryIO, result: ReadResult) -> None:
    """Stream the file through the sanitiser into the parser, stopping at the first damage."""
    builder = _Builder(result)
    parser = new_parser(builder)
    sanitiser = _Sanitiser(result)
    _counts.invalid = 0
    while True:
        chunk = handle.read(CHUNK_BYTES)
        result.size += len(chunk)
        final = not chunk
        if result.size > MAX_READ_BYTES and not final:
            total = result.size + _remaining(handle)
            result.problems.append(
                f"only the first {MAX_READ_BYTES // (1024 * 1024)} MiB of {total} bytes "
                "were read: the file is too large to be a useful result"
            )
            break
        try:
            data = sanitiser.feed(chunk, final)
            builder.fed += len(data)
            builder.count_expansion = sanitiser.doctype_kept
            parser.feed(data)
            if sanitiser.markup.damage is not None:
                result.problems.append(sanitiser.markup.damage)
                break
            if final:
                parser.close()
        except _Stop as stop:
            result.problems.append(str(stop))
            break
        except etree.XMLSyntaxError as error:
            if sanitiser.in_prolog:
                result.problems.append("not XML (no element found in it)")
            elif not (builder.root_closed and "Extra content" in str(error)):
                result.problems.append(_describe(error, builder, result))
            else:
                result.problems.append(
                    "content after the root element (a second root?) was ignored"
                )
            break
        if final:
            break
    sanitiser.finish()
    builder.finish()


def _remaining(handle: BinaryIO) -> int:
    try:
        return max(os.fstat(handle.fileno()).st_size - handle.tell(), 0)
    except OSError:
        return 0


def _message(error: etree.XMLSyntaxError) -> str:
    return str(error.msg if hasattr(error, "msg") else error).strip()


def _describe(error: etree.XMLSyntaxError, builder: _Builder, result: ReadResult) -> str:
    message = _message(error)
    if _ENTITY_BOMB.search(message):
        # Where libxml2 says it stopped is inside the entity, not a line of the file.
        return (
            "entity references expand too far, too deep or in a loop (an entity bomb?): "
            f"reading stopped there (libxml2: {message})"
        )
    where = f"line {error.lineno}" if getattr(error, "lineno", None) else "somewhere"
    if result.root_tag is None:
        return f"not XML ({message} at {where})"
    if builder.stack:
        return f"the file is cut off or broken at {where} ({message}); what came before is kept"
    return f"not well-formed at {where}: {message}"
