r"""Text made fit to show, and text bounded in size: one definition of each, at the bottom.

A command argument, a folder, an ``--env`` value or a planted record may hold any
bytes; Python carries those that were not UTF-8 as lone surrogates
(``surrogateescape``), which ``encode()`` refuses and no reader should see. The runner's
lines, its result files and ``status`` all show them the same way: as ``\xNN``, and a
character a reader must not get raw (a control, one XML forbids) as its code point the
same way. A text too long to keep keeps its head and tail around a mark saying how much
was cut, wherever it is cut. Every layer (xunit, domain_coordinator, runner) imports
these from here. On the RUNNER path: it imports nothing.
"""

from __future__ import annotations

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = [
    "CUT_MARK",
    "DISPLAY_LIMIT",
    "BoundedText",
    "bounded",
    "cut_mark",
    "display_text",
    "json_string",
    "shell_join",
    "shown",
    "shown_code",
]

#: surrogateescape's stand-ins for the bytes 0x80-0xFF: the byte is known.
_BYTE_FIRST, _BYTE_LAST = "\udc80", "\udcff"
_SURROGATE_FIRST, _SURROGATE_LAST = "\ud800", "\udfff"
#: Where a text was cut: ``{cut}`` is the count of characters left out.
CUT_MARK = "\n[... {cut} characters cut ...]\n"
#: JSON string escapes: quote, backslash and every control character.
_JSON_ESCAPES = {ord('"'): '\\"', ord("\\"): "\\\\"} | {
    code: f"\\u{code:04x}" for code in range(0x20)
}
#: Longest text :func:`display_text` shows by default (a holder record's command).
DISPLAY_LIMIT = 2000


def shown_code(code: int) -> str:
    r"""A code point that must not be written raw, shown: ``\x1b``, ``\ud800``, ``\U000e0001``.

    Python's own escapes (``backslashreplace``), so a byte shows as ``\xNN`` here and in
    :func:`shown` alike.
    """
    if code <= 0xFF:
        return f"\\x{code:02x}"
    return f"\\u{code:04x}" if code <= 0xFFFF else f"\\U{code:08x}"


def shown(text: str) -> str:
    r"""``text`` with every lone surrogate shown: a byte that was not UTF-8 as ``\xNN``.

    A surrogate no byte stands for (a JSON ``"\ud800"``) is shown as ``\udNNN``. The
    result holds no surrogate, so ``shown(text).encode()`` never fails. Everything else
    (controls included) is left as it is: each caller knows what its output forbids.
    """
    if text.isascii():
        return text
    try:
        raw = text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:
        raw = "".join(
            shown_code(ord(char)) if _stands_for_no_byte(char) else char for char in text
        ).encode("utf-8", "surrogateescape")
    return raw.decode("utf-8", "backslashreplace")


def _stands_for_no_byte(char: str) -> bool:
    return _SURROGATE_FIRST <= char <= _SURROGATE_LAST and not (_BYTE_FIRST <= char <= _BYTE_LAST)


def display_text(text: str, limit: int = DISPLAY_LIMIT) -> str:
    r"""``text`` safe to print on one line: every non-printable character as an escape.

    A control character (``\r``, ``\n``, ``\x1b``...) from a planted record or a file
    name could forge a line of ``status`` or ``report`` or drive a terminal; it is shown
    by :func:`shown_code`, a byte that was not UTF-8 (a lone surrogate) as :func:`shown`
    shows it. Longer texts keep their first ``limit`` characters and say how many were cut.
    """
    text = bounded(text, limit, head=limit, tail=0, mark="... ({cut} more characters)")
    if text.isprintable():
        return text
    return "".join(char if char.isprintable() else shown_code(ord(char)) for char in shown(text))


def json_string(text: str, ascii_only: bool = False) -> str:
    r"""``text`` as a JSON string literal; lone surrogates (undecodable bytes) as ``\uXXXX``.

    For the records runners write on a test's path, where ``json`` is not imported. With
    ``ascii_only`` every other non-ASCII character is escaped too (as ``json.dumps`` does).
    """
    escaped = text.translate(_JSON_ESCAPES)
    if ascii_only:
        if not escaped.isascii():
            escaped = "".join(_json_ascii(char) for char in escaped)
        return f'"{escaped}"'
    try:
        escaped.encode("utf-8")
    except UnicodeEncodeError:
        escaped = "".join(
            f"\\u{ord(char):04x}" if 0xD800 <= ord(char) <= 0xDFFF else char for char in escaped
        )
    return f'"{escaped}"'


def _json_ascii(char: str) -> str:
    r"""``char`` as ASCII JSON: itself, ``\uXXXX``, or a surrogate pair past U+FFFF."""
    code = ord(char)
    if code < 0x80:
        return char
    if code <= 0xFFFF:
        return f"\\u{code:04x}"
    code -= 0x10000
    return f"\\u{0xD800 + (code >> 10):04x}\\u{0xDC00 + (code & 0x3FF):04x}"


def cut_mark(cut: int, mark: str = CUT_MARK) -> str:
    """``mark`` saying that ``cut`` characters were left out there."""
    return mark.replace("{cut}", str(cut))


def bounded(
    text: str,
    limit: int,
    *,
    head: int | None = None,
    tail: int | None = None,
    mark: str = CUT_MARK,
) -> str:
    """``text`` when it has at most ``limit`` characters; else its head and tail around ``mark``.

    ``head`` and ``tail`` characters are kept (half of ``limit`` each by default, as
    :class:`BoundedText` keeps them); ``{cut}`` in ``mark`` becomes how many were left out.
    """
    if len(text) <= limit:
        return text
    half = max(limit // 2, 1)
    head = half if head is None else head
    tail = half if tail is None else tail
    cut = len(text) - head - tail
    if cut <= 0:
        return text
    return text[:head] + cut_mark(cut, mark) + text[len(text) - tail :]


class BoundedText:
    """Accumulates text in pieces, keeping at most ``limit`` characters (head + tail).

    A gigabyte of system-out costs a few kilobytes and still shows how it began and
    ended: the text :func:`bounded` keeps of the whole, built without holding it.
    """

    def __init__(self, limit: int) -> None:
        self._half = max(limit // 2, 1)
        self._head: list[str] = []
        self._head_size = 0
        self._tail = ""
        self.total = 0

    def add(self, piece: str) -> None:
        """Append a piece; linear in its size whatever has been added before."""
        self.total += len(piece)
        room = self._half - self._head_size
        if room > 0:
            taken = piece[:room]
            self._head.append(taken)
            self._head_size += len(taken)
            piece = piece[room:]
        if piece:
            self._tail = (self._tail + piece)[-self._half :]

    @property
    def cut(self) -> int:
        """Characters dropped between head and tail."""
        return self.total - self._head_size - len(self._tail)

    def value(self) -> str:
        """The kept text, with a marker where characters were dropped."""
        head = "".join(self._head)
        if self.cut > 0:
            return head + cut_mark(self.cut) + self._tail
        return head + self._tail


#: What a shell takes literally, as ``shlex.quote`` decides it (``[\w@%+=:,./-]``, ASCII).
_SHELL_SAFE = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_@%+=:,./-")


def shell_join(words: Iterable[str]) -> str:
    """``shlex.join``: the command as a shell line, each word quoted only where it must be.

    Written here because the RUNNER shows every test's command and ``shlex`` costs a
    quarter of a millisecond to import.
    """
    return " ".join(_shell_quote(word) for word in words)


def _shell_quote(word: str) -> str:
    if not word:
        return "''"
    if all(char in _SHELL_SAFE for char in word):
        return word
    return "'" + word.replace("'", "'\"'\"'") + "'"
