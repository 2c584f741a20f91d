"""Bytes made safe before the parser sees them: decoded, cleaned, the prolog defused.

The first stage of reading. Whatever the file holds (any encoding, bytes that are not
text, characters XML forbids raw or as references, colour codes, DTD markup), what
reaches the parser is clean UTF-8 with at most one DOCTYPE, one the parser can read.
Apart from the parser (``safe_parser``) and from what the elements mean (``builder``):
it works on text, streaming, and keeps a chunk boundary from cutting a reference or a
keyword.
"""

from __future__ import annotations

import codecs
import contextlib
import re
import threading

from lxml import etree

from ros_isolated_test.text import shown_code
from ros_isolated_test.xunit import xml_text
from ros_isolated_test.xunit.markup import MAX_ATTRIBUTES, Markup
from ros_isolated_test.xunit.raw import ReadResult
from ros_isolated_test.xunit.safe_parser import message, new_parser

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
#: Where the scan for a DOCTYPE's end stops: in its head, in its internal subset, in
#: one markup declaration.
_DOCTYPE_MARK = re.compile("[\"'\\[>]")
_SUBSET_MARK = re.compile("[\"'<\\]]")
_DECLARATION_MARK = re.compile("[\"'>]")
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


class Sanitiser:
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
        self.markup = Markup()
        _counts.invalid = 0  # what the decoder's error handler counts, for this file

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
                f"a DOCTYPE the parser cannot read ({message(error)}) was dropped: "
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
