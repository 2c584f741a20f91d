"""Huge markup bounded in the text stream, before the parser would buffer it whole.

lxml's parser holds a start tag, an attribute value, a comment or a CDATA section whole
before it reports it, so one such piece of a hostile file costs memory of its size.
Apart from the ``sanitiser`` (which feeds it) because it reads the text as markup,
a small state machine of its own, where the sanitiser only decodes and cleans characters.
"""

from __future__ import annotations

import re

from ros_isolated_test.text import cut_mark
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT

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


class Markup:
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
