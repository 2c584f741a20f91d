"""Text that XML 1.0 can carry: one definition, used by the reader and the writer alike."""

from __future__ import annotations

import re
from functools import cache

from ros_isolated_test.text import bounded, shown_code

#: Characters kept of one text (a message, a failure's text, a system-out).
TEXT_LIMIT = 64 * 1024


@cache
def ansi_escape() -> re.Pattern[str]:
    """Colour and cursor codes: noise in a report, and ESC is illegal in XML anyway.

    Compiled on first use, as the next one: most runs never write a character they match.
    """
    return re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b[@-Z\\-_]")


@cache
def rare_illegal() -> re.Pattern[str]:
    """The illegal characters above 0x1F, and U+FFFD, which xunit-viewer cannot take."""
    return re.compile("[\ud800-\udfff\ufffd-\uffff]")


def legal(code: int) -> bool:
    """Whether XML 1.0 allows the code point, raw or as a character reference."""
    return (
        code in (0x9, 0xA, 0xD)
        or 0x20 <= code <= 0xD7FF
        or 0xE000 <= code <= 0xFFFD
        or 0x10000 <= code <= 0x10FFFF
    )


#: str.translate table showing every C0 control XML forbids, at C speed.
CONTROL_TABLE = {code: shown_code(code) for code in range(0x20) if code not in (0x9, 0xA, 0xD)}


def xml_safe(text: str, limit: int | None = None) -> str:
    """Text any XML 1.0 reader accepts: colour codes dropped, other illegal characters shown.

    Over ``limit`` the head and tail are kept around a marked cut.
    """
    if "\x1b" in text:
        text = ansi_escape().sub("", text)
    text = text.translate(CONTROL_TABLE)
    if not text.isascii() and rare_illegal().search(text):
        text = rare_illegal().sub(lambda match: shown_code(ord(match.group())), text)
    return text if limit is None else bounded(text, limit)


def name_token(text: str, default: str, limit: int = 512) -> str:
    """A name every reader takes: one line, no edge spaces, bounded, never empty."""
    text = " ".join(xml_safe(text).split())
    return bounded(text, limit, mark=" [...] ") or default
