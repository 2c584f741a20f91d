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

from ros_isolated_test.xunit import xml_text
from ros_isolated_test.xunit.bounded_text import BoundedText, bounded
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
#: Elements nested deeper than this stop reading. Real producers nest four or five levels
#: (testsuites, testsuite, testcase, failure); the parser keeps a few words per open
#: element, so an unbounded depth costs memory in proportion to the file.
MAX_DEPTH = 1000
#: The attributes the normaliser reads; the others are not kept.
_CASE_KEYS = frozenset({"name", "classname", "time", "status", "result"})
_OUTCOME_KEYS = frozenset({"message", "type"})

_ATTEMPT_TAGS = frozenset({"rerunFailure", "rerunError", "flakyFailure", "flakyError"})
OUTCOME_TAGS = frozenset({"failure", "error", "skipped"}) | _ATTEMPT_TAGS
#: A character reference, unless it is one of the many that are legal at a glance (32 to
#: 49999, 0x20 to 0xCFFF): those pass in C, not through a Python call each.
_CHAR_REF = re.compile(
    r"&#(?!0*(?:3[2-9]|[4-9][0-9]|[1-9][0-9]{2,3}|[1-4][0-9]{4});"
    r"|x0*(?:[2-9a-fA-F][0-9a-fA-F]|[1-9a-cA-C][0-9a-fA-F]{2,3});)"
    r"(?:x([0-9a-fA-F]{1,8})|([0-9]{1,10}));"
)
_OPEN_CHAR_REF = re.compile(r"&#x?[0-9a-fA-F]{0,10}$")
#: Markup that declares a DTD or entities: never allowed to reach the parser.
_DTD_MARKUP = re.compile(r"<!(?=DOCTYPE|ENTITY|ELEMENT|ATTLIST|NOTATION)")
#: A DOCTYPE's internal entities are expanded, as text, when they are small: the prolog
#: is looked at up to PROLOG_LIMIT characters, one entity's text may reach ENTITY_LIMIT
#: characters (nesting ENTITY_DEPTH deep) and all expansions in one file ENTITY_BUDGET.
#: Beyond those (an entity bomb), and for external entities, which are never read, an
#: entity stays undefined: the file reads as damaged at its first use of it.
PROLOG_LIMIT = 64 * 1024
ENTITY_LIMIT = 4096
ENTITY_BUDGET = 1024 * 1024
ENTITY_DEPTH = 32
_ENTITY_NAME = r"[A-Za-z_:][A-Za-z0-9._:-]{0,63}"
#: An entity declaration up to its value; group 1 marks a parameter entity.
_ENTITY_HEAD = re.compile(rf"<!ENTITY[ \t\r\n]+(%[ \t\r\n]+)?({_ENTITY_NAME})[ \t\r\n]+")
#: Where a scan of a DOCTYPE (before its internal subset) or of one declaration stops.
_DOCTYPE_MARK = re.compile("[\"'\\[>]")
_DECLARATION_MARK = re.compile("[\"'>]")
_SUBSET_MARK = re.compile("[<\\]]")
_ENTITY_REFERENCE = re.compile(rf"&({_ENTITY_NAME});")
_OPEN_ENTITY_REFERENCE = re.compile(rf"&(?:{_ENTITY_NAME})?$")
_LEGAL_CHAR_REF = re.compile(r"&#(?:x([0-9a-fA-F]{1,8})|([0-9]{1,10}));")
_PREDEFINED = {"amp": "&", "lt": "<", "gt": ">", "quot": '"', "apos": "'"}
_ESCAPED = str.maketrans({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&apos;"})
#: Where the prolog scan stops inside a DOCTYPE: a tag, or a quoted literal to skip.
_PROLOG_MARK = re.compile("[<\"']")
_ENCODING = re.compile(rb"""^<\?xml[^>]*encoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")
_counts = threading.local()


def _count_and_show(error: UnicodeError) -> tuple[str, int]:
    r"""Show each undecodable byte as ``\xNN``, never as U+FFFD.

    A literal U+FFFD makes xunit-viewer guess the file is CP1252 and abort its run.
    """
    assert isinstance(error, UnicodeDecodeError)
    bad = error.object[error.start : error.end]
    _counts.invalid = getattr(_counts, "invalid", 0) + len(bad)
    return "".join(f"\\x{byte:02x}" for byte in bad), error.end


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


class _TooDeep(Exception):
    """Raised from the parser's start event: lxml stops the parser and re-raises it."""


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

    def start(self, tag: str, attrib: object) -> None:
        if len(self.stack) >= MAX_DEPTH:
            raise _TooDeep
        name = _local(tag)
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
            out.append(f"&#10;[... {self.cut} characters cut ...]&#10;")
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
        self.entities = _Entities()

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
            out.append(self.entities.substitute(plain.group()))
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
            self.value.add(self.entities.substitute(text[pos:stop]), out)
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


class _Entities:
    """A DOCTYPE's small internal entities, put into text and attribute values as text.

    Producers rarely declare entities, but one that does (a message kept in one place)
    must not lose its failure's text: without them the parser stops at the first use.
    The declarations are read from the prolog here, never by the parser, so nothing
    external is loaded; an entity's markup, if any, is kept as text.
    """

    def __init__(self) -> None:
        self.prolog: list[str] = []
        self.size = 0
        self.escaped: dict[str, str] = {}
        self.used = 0
        self.over_budget = 0

    def capture(self, text: str) -> None:
        """Keep prolog text (bounded) to look for declarations once the root starts."""
        room = PROLOG_LIMIT + 1 - self.size
        if room > 0 and text:
            self.prolog.append(text[:room])
            self.size += min(len(text), room)

    def define(self) -> list[str]:
        """Expand the declared entities; returns what to report about them."""
        prolog = "".join(self.prolog)
        self.prolog = []
        notes = []
        if self.size > PROLOG_LIMIT:
            notes.append(
                f"the prolog is over {PROLOG_LIMIT} characters: entities declared beyond "
                "that were not expanded"
            )
        literals = _declared_literals(prolog)
        values: dict[str, str | None] = {}
        for name in literals:
            self._expand(name, literals, values, ())
        self.escaped = {
            name: value.translate(_ESCAPED) for name, value in values.items() if value is not None
        }
        if self.escaped:
            notes.append(
                f"{len(self.escaped)} internal entit{'y' if len(self.escaped) == 1 else 'ies'} "
                f"of the DOCTYPE expanded as text: {', '.join(sorted(self.escaped)[:10])}"
            )
        refused = sorted(name for name, value in values.items() if value is None)
        if refused:
            notes.append(
                f"{len(refused)} entit{'y' if len(refused) == 1 else 'ies'} not expanded "
                f"(over {ENTITY_LIMIT} characters, recursive, nested over {ENTITY_DEPTH} "
                f"deep, or referring to one not expanded): {', '.join(refused[:10])}"
            )
        return notes

    def _expand(
        self,
        name: str,
        literals: dict[str, str | None],
        values: dict[str, str | None],
        open_names: tuple[str, ...],
    ) -> str | None:
        if name in values:
            return values[name]
        literal = literals.get(name)
        if literal is None or name in open_names or len(open_names) >= ENTITY_DEPTH:
            values[name] = None
            return None
        text = _LEGAL_CHAR_REF.sub(_character, literal)
        pieces: list[str] = []
        size, pos = 0, 0
        for match in _ENTITY_REFERENCE.finditer(text):
            reference = match.group(1)
            inner = _PREDEFINED.get(reference)
            if inner is None:
                inner = self._expand(reference, literals, values, (*open_names, name))
            size += match.start() - pos + len(inner or "")
            if inner is None or size > ENTITY_LIMIT:
                values[name] = None
                return None
            pieces += (text[pos : match.start()], inner)
            pos = match.end()
        pieces.append(text[pos:])
        value = "".join(pieces)
        values[name] = value if len(value) <= ENTITY_LIMIT else None
        return values[name]

    def substitute(self, text: str) -> str:
        """``text`` with each reference to an expanded entity replaced, within the budget."""
        if not self.escaped or "&" not in text:
            return text
        return _ENTITY_REFERENCE.sub(self._one, text)

    def _one(self, match: re.Match[str]) -> str:
        value = self.escaped.get(match.group(1))
        if value is None:
            return match.group()
        if self.used + len(value) > ENTITY_BUDGET:
            self.over_budget += 1
            return match.group()
        self.used += len(value)
        return value


def _character(match: re.Match[str]) -> str:
    code = int(match.group(1), 16) if match.group(1) else int(match.group(2))
    return chr(code) if xml_text.legal(code) else match.group()


def _declared_literals(prolog: str) -> dict[str, str | None]:
    """The general entities declared at the top level of the DOCTYPE's internal subset.

    Scanned as a parser reads it, in linear time: quoted literals, comments and processing
    instructions are skipped whole, so a declaration inside one defines nothing, nor does
    one inside a parameter entity, which is never expanded. The five predefined entities
    are never redefined: the sanitiser's own ``&lt;`` must stay ``<``. ``None``: a value
    over ENTITY_LIMIT characters, or not ending within the prolog kept.
    """
    literals: dict[str, str | None] = {}
    pos = _internal_subset(prolog)
    while pos >= 0:
        mark = _SUBSET_MARK.search(prolog, pos)
        if mark is None or mark.group() == "]":
            break
        start = mark.start()
        if prolog.startswith(("<!--", "<?"), start):
            pos = _after(prolog, "-->" if prolog[start + 1] == "!" else "?>", start + 2)
            continue
        head = _ENTITY_HEAD.match(prolog, start)
        pos = head.end() if head else start + 1
        if head and pos < len(prolog) and prolog[pos] in "\"'":
            end = prolog.find(prolog[pos], pos + 1)
            name, value = head.group(2), prolog[pos + 1 : end] if end >= 0 else None
            if not head.group(1) and name not in _PREDEFINED:
                # The first declaration of a name binds (XML 1.0, section 4.2); a value
                # ending beyond the kept prolog is over the limit too.
                too_long = value is None or len(value) > ENTITY_LIMIT
                literals.setdefault(name, None if too_long else value)
            if end < 0:
                break  # all that follows is inside the literal
            pos = end + 1
        pos = _declaration_end(prolog, pos)
    return literals


def _internal_subset(prolog: str) -> int:
    """Where the DOCTYPE's internal subset starts, past its ``[``; -1 if it has none."""
    pos = 0
    while (start := prolog.find("<", pos)) >= 0:
        if prolog.startswith(("<!--", "<?"), start):
            pos = _after(prolog, "-->" if prolog[start + 1] == "!" else "?>", start + 2)
            if pos < 0:
                return -1
        elif prolog.startswith("<!DOCTYPE", start):
            pos = start + 9
            while mark := _DOCTYPE_MARK.search(prolog, pos):
                if mark.group() == "[":
                    return mark.end()
                if mark.group() == ">":
                    return -1
                pos = _after(prolog, mark.group(), mark.end())
                if pos < 0:
                    return -1
            return -1
        else:
            pos = start + 1
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
        self.doctype = False
        #: Quoted literals of a DOCTYPE are skipped (an entity's value may hold "<b>"),
        #: unless one runs longer than PROLOG_LIMIT: then quotes are no longer heeded.
        self.heed_quotes = True
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
            if open_reference := _OPEN_ENTITY_REFERENCE.search(tail):
                held.append(open_reference.start())
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
        if self.in_prolog:
            text, unfinished = self._skip_prolog(text, final)
            self.carry = unfinished + self.carry
        if "<!" in text:
            # Anything DTD-like left (smuggled, late, unterminated) is made inert: the
            # parser then reports broken markup instead of defining entities.
            text, found = _DTD_MARKUP.subn("&lt;!", text)
            if found:
                self.result.repairs.append(
                    "DTD markup was made inert: DTDs and entities are never loaded or expanded"
                )
        return self.markup.feed(text, final).encode("utf-8")

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
        return xml_text.shown_code(ord(match.group()))

    def _show_reference(self, match: re.Match[str]) -> str:
        code = int(match.group(1), 16) if match.group(1) else int(match.group(2))
        if xml_text.legal(code) and code != 0xFFFD:
            return match.group()
        self.illegal += 1
        return xml_text.shown_code(code)

    def _skip_prolog(self, text: str, final: bool = False) -> tuple[str, str]:
        """Drop everything before the root element, streaming: nothing there is needed.

        The prolog may only hold the declaration (we re-encode anyway), comments,
        processing instructions and a DOCTYPE, which must never reach the parser: it
        could define entities (bombs) or point at files and the network; its small
        internal entities are read from the text kept here (:class:`_Entities`). Returns
        the text from the root element on, and an unfinished tail to look at again.
        """
        index = 0
        entities = self.markup.entities
        while True:
            if self.in_comment:
                end = text.find("-->", index)
                if end < 0:
                    self.prolog_lines += text.count("\n", 0, len(text) - 2)
                    entities.capture(text[:-2])
                    return "", text[-2:]
                index, self.in_comment = end + 3, False
                continue
            if self.doctype and self.heed_quotes:
                mark = _PROLOG_MARK.search(text, index)
                start = mark.start() if mark else -1
                if mark and mark.group() != "<":
                    quote = start
                    end = text.find(text[quote], quote + 1, quote + 1 + PROLOG_LIMIT)
                    if end >= 0:
                        index = end + 1
                    elif final or len(text) - quote > PROLOG_LIMIT:
                        # Unterminated: a broken DOCTYPE, read on as if unquoted.
                        self.heed_quotes, index = False, quote + 1
                    else:
                        self.prolog_lines += text.count("\n", 0, quote)
                        entities.capture(text[:quote])
                        return "", text[quote:]  # the literal ends in a later chunk
                    continue
            else:
                start = text.find("<", index)
            if start < 0 or start + 1 >= len(text):
                kept = len(text) if start < 0 else start
                self.prolog_lines += text.count("\n", 0, kept)
                entities.capture(text[:kept])
                return "", text[kept:]
            if len(text) - start < 9 and "<!DOCTYPE".startswith(text[start:]):
                self.prolog_lines += text.count("\n", 0, start)
                entities.capture(text[:start])
                return "", text[start:]  # a keyword cut by the chunk boundary
            if text.startswith("<!--", start):
                self.in_comment, index = True, start + 4
                continue
            if text.startswith("<!DOCTYPE", start) and not self.doctype:
                self.doctype = True
                self.result.repairs.append(
                    "a DOCTYPE was removed: no DTD or external entity is ever loaded"
                )
            after = text[start + 1]
            if after.isalpha() or after in "_:":
                self.in_prolog = False
                entities.capture(text[:start])
                if self.doctype:
                    self.result.repairs.extend(entities.define())
                # Keep the line count, so the parser's line numbers match the file's.
                lines = min(self.prolog_lines + text.count("\n", 0, start), 100_000)
                return "\n" * lines + text[start:], ""
            index = start + 1

    def finish(self) -> None:
        if self.markup.entities.over_budget:
            self.result.repairs.append(
                f"{self.markup.entities.over_budget} entity reference(s) beyond "
                f"{ENTITY_BUDGET} expanded characters were not expanded"
            )
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
    if path.is_dir():
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


def _parse(handle: BinaryIO, result: ReadResult) -> None:
    """Stream the file through the sanitiser into the parser, stopping at the first damage."""
    builder = _Builder(result)
    parser = etree.XMLParser(
        target=cast("etree.ParserTarget", builder),
        # Safe only because no DTD markup reaches the parser: no entity is defined but
        # the five predefined ones, which attribute values need resolved.
        resolve_entities=True,
        no_network=True,
        load_dtd=False,
        huge_tree=True,
        remove_pis=True,
    )
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
            parser.feed(sanitiser.feed(chunk, final))
            if sanitiser.markup.damage is not None:
                result.problems.append(sanitiser.markup.damage)
                break
            if final:
                parser.close()
        except _TooDeep:
            result.problems.append(
                f"elements nest deeper than {MAX_DEPTH} levels: not a result file; "
                "reading stopped there"
            )
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


def _describe(error: etree.XMLSyntaxError, builder: _Builder, result: ReadResult) -> str:
    message = str(error.msg if hasattr(error, "msg") else error).strip()
    where = f"line {error.lineno}" if getattr(error, "lineno", None) else "somewhere"
    if result.root_tag is None:
        return f"not XML ({message} at {where})"
    if builder.stack:
        return f"the file is cut off or broken at {where} ({message}); what came before is kept"
    return f"not well-formed at {where}: {message}"
