"""Text that XML 1.0 can carry: one definition, used by the reader and the writer alike."""

from __future__ import annotations

import re

from ros_isolated_test.runner.bounded_text import bounded

#: Colour and cursor codes: noise in a report, and ESC is illegal in XML anyway.
ANSI_ESCAPE = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b[@-Z\\-_]")
ILLEGAL_CHAR = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def legal(code: int) -> bool:
    """Whether XML 1.0 allows the code point, raw or as a character reference."""
    return (
        code in (0x9, 0xA, 0xD)
        or 0x20 <= code <= 0xD7FF
        or 0xE000 <= code <= 0xFFFD
        or 0x10000 <= code <= 0x10FFFF
    )


def shown_code(code: int) -> str:
    r"""How a code point XML cannot carry is written instead: ``\x1b``, ``\ud800``."""
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def xml_safe(text: str, limit: int | None = None) -> str:
    """Text any XML 1.0 reader accepts: colour codes dropped, other illegal characters shown.

    Over ``limit`` the head and tail are kept around a marked cut.
    """
    text = ANSI_ESCAPE.sub("", text)
    text = ILLEGAL_CHAR.sub(lambda match: shown_code(ord(match.group())), text)
    return text if limit is None else bounded(text, limit)
