r"""One rule for bytes that were not UTF-8, wherever the runner shows text: ``\xNN``.

Runner lines (capture), result files (result_file) and ``status`` (holder) all use
:func:`ros_isolated_test.text.shown`, so a byte shows the same everywhere.
"""

from __future__ import annotations

import os

import pytest

from ros_isolated_test.text import shown


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("plain", "plain"),  # the control: nothing to show, returned as it is
        ("caf\u00e9 \u2713 \x1b[0m\n", "caf\u00e9 \u2713 \x1b[0m\n"),  # controls are the caller's
        (os.fsdecode(b"caf\xe9"), "caf\\xe9"),  # a Latin-1 folder name
        # A surrogate no byte stands for (planted JSON) beside one that does: each its way.
        ("\ud800 and \udce9", "\\ud800 and \\xe9"),
    ],
)
def test_bytes_that_were_not_utf8_are_shown_as_xnn(text: str, expected: str) -> None:
    assert shown(text) == expected
    shown(text).encode()  # never refused: no surrogate is left


def test_bytes_that_form_utf8_again_are_the_character_they_spell() -> None:
    """Bytes are shown as the text they were: only those that are not UTF-8 are escaped."""
    assert shown(os.fsdecode(b"\xc3\xa9\xff")) == "\u00e9\\xff"
