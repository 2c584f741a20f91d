r"""Text that may carry bytes which were not UTF-8, made fit to show: one rule for all.

A command argument, a folder, an ``--env`` value or a planted record may hold any
bytes; Python carries those that were not UTF-8 as lone surrogates
(``surrogateescape``), which ``encode()`` refuses and no reader should see. The runner's
lines, its result files and ``status`` all show them the same way: as ``\xNN``. On the
RUNNER path: it imports nothing.
"""

from __future__ import annotations

__all__ = ["shown"]

#: surrogateescape's stand-ins for the bytes 0x80-0xFF: the byte is known.
_BYTE_FIRST, _BYTE_LAST = "\udc80", "\udcff"
_SURROGATE_FIRST, _SURROGATE_LAST = "\ud800", "\udfff"


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
            f"\\u{ord(char):04x}" if _stands_for_no_byte(char) else char for char in text
        ).encode("utf-8", "surrogateescape")
    return raw.decode("utf-8", "backslashreplace")


def _stands_for_no_byte(char: str) -> bool:
    return _SURROGATE_FIRST <= char <= _SURROGATE_LAST and not (_BYTE_FIRST <= char <= _BYTE_LAST)
