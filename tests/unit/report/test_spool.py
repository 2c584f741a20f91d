"""``report.spool``: a part of the output kept on disk, copied out whole or in part."""

from __future__ import annotations

import io

import pytest

from ros_isolated_test.report import spool as spool_module
from ros_isolated_test.report.spool import Spool


def test_a_spool_copies_any_part_of_what_was_written() -> None:
    spool = Spool()
    try:
        spool.write("héllo ")
        spool.write("world")
        assert spool.size == len("héllo world".encode())
        whole, part = io.BytesIO(), io.BytesIO()
        spool.copy_to(whole)
        spool.copy_to(part, offset=len("héllo ".encode()), length=3)
        assert (whole.getvalue().decode(), part.getvalue()) == ("héllo world", b"wor")
        spool.write("!")  # after a copy, writing goes on at the end
        again = io.BytesIO()
        spool.copy_to(again)
        assert again.getvalue().decode() == "héllo world!"
    finally:
        spool.close()


def test_text_is_copied_in_bounded_pieces_and_a_character_is_never_split(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A chunk of 3 bytes splits the characters: the decoder joins them again.
    monkeypatch.setattr(spool_module, "_COPY_CHUNK", 3)
    spool = Spool()
    try:
        spool.write("é" * 10 + "€")  # two- and three-byte characters
        pieces: list[str] = []
        spool.copy_text(pieces.append)
        assert "".join(pieces) == "é" * 10 + "€"
        # Each piece: a chunk, and the bytes of a character the chunk before had cut.
        assert max(len(piece.encode()) for piece in pieces) <= 3 + 2
        spool.write("!")
        again: list[str] = []
        spool.copy_text(again.append)
        assert "".join(again).endswith("€!")
    finally:
        spool.close()
