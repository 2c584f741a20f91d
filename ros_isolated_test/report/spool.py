"""A part of the output kept on disk while the files are read, so memory stays bounded.

Both the page and the printed report say things in an order other than the one the
files are read in (the totals first, the flaky cases after every file): each part is
written to a spool (a temporary file) as it is found and copied out at the end.
"""

from __future__ import annotations

import codecs
import os
import tempfile
from collections.abc import Callable, Iterator
from typing import IO

_COPY_CHUNK = 1 << 20


class Spool:
    """A temporary file written as UTF-8 that knows its length: a part of the output."""

    def __init__(self) -> None:
        self.file: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115 (closed by close)
        self.size = 0

    def write(self, text: str) -> None:
        data = text.encode("utf-8", "backslashreplace")
        self.file.write(data)
        self.size += len(data)

    def copy_to(self, out: IO[bytes], offset: int = 0, length: int | None = None) -> None:
        """Bytes ``offset`` to ``offset + length`` (default: to the end) into ``out``."""
        for chunk in self._chunks(offset, length):
            out.write(chunk)

    def copy_text(self, put: Callable[[str], object]) -> None:
        """Everything written, as text in pieces of bounded size, to ``put``."""
        decoder = codecs.getincrementaldecoder("utf-8")("replace")
        for chunk in self._chunks(0, None):
            put(decoder.decode(chunk))
        put(decoder.decode(b"", final=True))

    def _chunks(self, offset: int, length: int | None) -> Iterator[bytes]:
        """The bytes from ``offset``, ``length`` of them, a megabyte at a time."""
        self.file.flush()
        self.file.seek(offset)
        left = self.size - offset if length is None else length
        while left > 0:
            chunk = self.file.read(min(left, _COPY_CHUNK))
            if not chunk:
                break
            left -= len(chunk)
            yield chunk
        self.file.seek(0, os.SEEK_END)  # writing goes on at the end

    def close(self) -> None:
        self.file.close()
