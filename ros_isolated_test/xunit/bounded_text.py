"""Text that may be arbitrarily long on the way in and is small on the way out.

Keeps the head and the tail, counts what was cut between them and marks the cut, so a
gigabyte of system-out costs a few kilobytes and still shows how it began and ended.
"""

from __future__ import annotations


class BoundedText:
    """Accumulates text in pieces, keeping at most ``limit`` characters (head + tail)."""

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
            return f"{head}\n[... {self.cut} characters cut ...]\n{self._tail}"
        return head + self._tail


def bounded(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters the same way :class:`BoundedText` cuts it."""
    if len(text) <= limit:
        return text
    accumulator = BoundedText(limit)
    accumulator.add(text)
    return accumulator.value()
