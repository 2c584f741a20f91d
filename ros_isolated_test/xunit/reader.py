"""Reading a result file written by arbitrary code: bounded, offline, and never giving up.

A test's result file may be broken or hostile: invalid UTF-8, characters XML forbids
(raw or as references), an entity bomb, a DTD that points at the network, two roots,
a cut-off end, gigabytes of output, a directory instead of a file. Everything is read
as a stream through a sanitiser into a strict parser whose events build a small raw
model; what cannot be read is described in ``problems`` and whatever came before it is
kept. Memory is bounded by the caps below, not by the file.
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
#: Test cases kept in full; later ones are only counted.
MAX_CASES = 5000
#: Each text keeps up to TEXT_LIMIT characters until all texts together reach this;
#: after that each keeps only SMALL_TEXT_LIMIT.
TEXT_BUDGET = 2 * 1024 * 1024
SMALL_TEXT_LIMIT = 200
NAME_LIMIT = 256

OUTCOME_TAGS = frozenset(
    {"failure", "error", "skipped", "rerunFailure", "rerunError", "flakyFailure", "flakyError"}
)
_CHAR_REF = re.compile(r"&#(?:x([0-9a-fA-F]{1,8})|([0-9]{1,10}));")
_OPEN_CHAR_REF = re.compile(r"&#x?[0-9a-fA-F]{0,10}$")
#: Markup that declares a DTD or entities: never allowed to reach the parser.
_DTD_MARKUP = re.compile(r"<!(?=DOCTYPE|ENTITY|ELEMENT|ATTLIST|NOTATION)")
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


@dataclass
class RawOutcome:
    """A failure, error or skipped element as the producer wrote it."""

    tag: str
    attrs: dict[str, str]
    text: str


@dataclass
class RawCase:
    """A testcase element as the producer wrote it, texts already bounded."""

    attrs: dict[str, str]
    suite: str
    outcomes: list[RawOutcome] = field(default_factory=list)
    system_out: str = ""
    system_err: str = ""
    #: False when the file ended (or reading stopped) inside this case.
    complete: bool = True


@dataclass
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
    #: Outcomes (``passed``, ``failure``, ...) of cases beyond MAX_CASES, only counted.
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


class _Budget:
    def __init__(self) -> None:
        self.used = 0

    def text(self) -> BoundedText:
        return BoundedText(TEXT_LIMIT if self.used < TEXT_BUDGET else SMALL_TEXT_LIMIT)

    def take(self, text: BoundedText) -> str:
        value = text.value()
        self.used += len(value)
        return value

    def attrs(self, attrib: object) -> dict[str, str]:
        limit = TEXT_LIMIT if self.used < TEXT_BUDGET else SMALL_TEXT_LIMIT
        result: dict[str, str] = {}
        for key, value in dict(attrib).items():  # type: ignore[call-overload]
            name = _local(str(key))
            kept = bounded(str(value), NAME_LIMIT if name in ("name", "classname") else limit)
            self.used += len(kept)
            result[name] = kept
        return result


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


class _Builder:
    """Parser target: turns element events into the raw model, with bounded memory."""

    def __init__(self, result: ReadResult) -> None:
        self.result = result
        self.budget = _Budget()
        self.stack: list[str] = []
        self.suites: list[RawSuite] = []
        self.case: RawCase | None = None
        self.counting: str | None = None  # outcome of a case beyond MAX_CASES
        self.in_counted_case = False
        self.text: BoundedText | None = None
        self.outcome_attrs: dict[str, str] = {}
        self.root_closed = False

    def start(self, tag: str, attrib: object) -> None:
        name = _local(tag)
        self.stack.append(name)
        if len(self.stack) == 1:
            self.result.root_tag = name
            self.result.root_attrs = self.budget.attrs(attrib)
        parent = self.stack[-2] if len(self.stack) > 1 else None
        if name == "testsuite":
            attrs = self.budget.attrs(attrib)
            suite = RawSuite(attrs.get("name", ""), attrs)
            self.suites.append(suite)
            self.result.suites.append(suite)
        elif name == "testcase" and self.case is None and not self.in_counted_case:
            suite_name = self.suites[-1].name if self.suites else ""
            if len(self.result.cases) < MAX_CASES:
                self.case = RawCase(self.budget.attrs(attrib), suite_name)
            else:
                self.in_counted_case = True
                self.counting = "passed"
        elif self.in_counted_case and parent == "testcase" and name in OUTCOME_TAGS:
            self.counting = _worse(self.counting or "passed", name)
        elif self.case is not None and parent == "testcase":
            if name in OUTCOME_TAGS:
                self.outcome_attrs = self.budget.attrs(attrib)
                self.text = self.budget.text()
            elif name in ("system-out", "system-err"):
                self.text = self.budget.text()
        elif self.case is None and parent == "testsuite" and name in ("system-out", "system-err"):
            self.text = self.budget.text()

    def data(self, data: str | bytes) -> None:
        if self.text is not None:
            self.text.add(data if isinstance(data, str) else data.decode("utf-8", "replace"))

    def end(self, tag: str) -> None:
        name = _local(tag)
        if self.stack:
            self.stack.pop()
        parent = self.stack[-1] if self.stack else None
        if name == "testcase" and self.in_counted_case and parent != "testcase":
            self.result.dropped[self.counting or "passed"] += 1
            self.in_counted_case = False
            self.counting = None
        elif name == "testcase" and self.case is not None and parent != "testcase":
            self.result.cases.append(self.case)
            self.case = None
        elif self.text is not None and parent == "testcase" and self.case is not None:
            value = self.budget.take(self.text)
            if name in OUTCOME_TAGS:
                self.case.outcomes.append(RawOutcome(name, self.outcome_attrs, value))
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

    def comment(self, text: str | bytes) -> None:
        return None

    def close(self) -> None:
        return None

    def finish_open_case(self) -> None:
        """The file ended inside a test case: keep what it had, marked incomplete."""
        if self.case is not None:
            if self.text is not None and self.stack and self.stack[-1] in OUTCOME_TAGS:
                value = self.budget.take(self.text)
                self.case.outcomes.append(RawOutcome(self.stack[-1], self.outcome_attrs, value))
            self.case.complete = False
            self.result.cases.append(self.case)
            self.case = None


_RANK = {"passed": 0, "skipped": 1, "error": 2, "failure": 3}


def _worse(current: str, tag: str) -> str:
    kind = "failure" if "Failure" in tag or tag == "failure" else tag
    kind = "error" if "Error" in tag else kind
    return kind if _RANK.get(kind, 0) > _RANK.get(current, 0) else current


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
        self.prolog_lines = 0
        self.illegal = 0

    def feed(self, data: bytes, final: bool = False) -> bytes:
        text = self.carry + self._decode(data, final)
        self.carry = ""
        if not final:
            # Keep back a reference, colour code or DTD keyword cut by the chunk boundary.
            tail = text[-16:]
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
        if self.in_prolog:
            text, unfinished = self._skip_prolog(text)
            self.carry = unfinished + self.carry
        if "<!" in text:
            # Anything DTD-like left (smuggled, late, unterminated) is made inert: the
            # parser then reports broken markup instead of defining entities.
            text, found = _DTD_MARKUP.subn("&lt;!", text)
            if found:
                self.result.repairs.append(
                    "DTD markup was made inert: DTDs and entities are never loaded or expanded"
                )
        return text.encode("utf-8")

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

    def _skip_prolog(self, text: str) -> tuple[str, str]:
        """Drop everything before the root element, streaming: nothing there is needed.

        The prolog may only hold the declaration (we re-encode anyway), comments,
        processing instructions and a DOCTYPE, which must never reach the parser: it
        could define entities (bombs) or point at files and the network. Returns the
        text from the root element on, and an unfinished tail to look at again.
        """
        index = 0
        while True:
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
            if text.startswith("<!DOCTYPE", start) and not self.doctype:
                self.doctype = True
                self.result.repairs.append(
                    "a DOCTYPE was removed: DTDs and entities are never loaded or expanded"
                )
            following = text[start + 1]
            if following.isalpha() or following in "_:":
                self.in_prolog = False
                # Keep the line count, so the parser's line numbers match the file's.
                lines = min(self.prolog_lines + text.count("\n", 0, start), 100_000)
                return "\n" * lines + text[start:], ""
            index = start + 1

    def finish(self) -> None:
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
    stopped = False
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
            stopped = True
            break
        try:
            parser.feed(sanitiser.feed(chunk, final))
            if final:
                parser.close()
        except etree.XMLSyntaxError as error:
            if sanitiser.in_prolog:
                result.problems.append("not XML (no element found in it)")
            elif not (builder.root_closed and "Extra content" in str(error)):
                result.problems.append(_describe(error, builder, result))
            else:
                result.problems.append(
                    "content after the root element (a second root?) was ignored"
                )
            stopped = True
            break
        if final:
            break
    sanitiser.finish()
    if stopped or not builder.root_closed:
        builder.finish_open_case()


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
