r"""``text``: one rule for bytes that were not UTF-8, wherever the runner shows text: ``\xNN``.

Runner lines (capture), result files (result_file) and ``status`` (holder) all use
:func:`ros_isolated_test.text.shown`, so a byte shows the same everywhere; a code point
that must not be written raw is shown by the one :func:`shown_code`, and a text too long
to keep is cut by the one :func:`bounded`, wherever it is cut. The records runners write
on a test's path, without ``json``, are JSON all the same (:func:`json_string`).
"""

from __future__ import annotations

import json
import os
import shlex

import pytest

from ros_isolated_test.text import (
    BoundedText,
    bounded,
    display_text,
    json_string,
    shell_join,
    shown,
    shown_code,
)


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


@pytest.mark.parametrize(
    ("code", "expected"),
    [
        (0x1B, "\\x1b"),  # a control: XML forbids it, a terminal acts on it
        (0xE9, "\\xe9"),  # as shown() shows the byte 0xE9
        (0xD800, "\\ud800"),
        (0xFFFE, "\\ufffe"),
        (0xE0001, "\\U000e0001"),  # a tag character beyond U+FFFF: no \u with five digits
        (0x110000, "\\U00110000"),  # a character reference past Unicode
    ],
)
def test_a_code_point_is_shown_as_python_escapes_it(code: int, expected: str) -> None:
    assert shown_code(code) == expected
    if 0x80 <= code <= 0x10FFFF:  # Python's own escape, where it has one
        assert chr(code).encode("ascii", "backslashreplace").decode() == expected


def test_display_text_escapes_what_a_terminal_acts_on_and_keeps_the_rest() -> None:
    printable = "ros2 launch pkg a.py \u00fc \U0001f600"
    assert display_text(printable) == printable
    assert display_text("a\tb\x7f\x9b\u2028\u202e") == "a\\x09b\\x7f\\x9b\\u2028\\u202e"
    assert display_text("caf\udce9") == "caf\\xe9"  # an undecodable byte
    assert display_text("tag\U000e0001") == "tag\\U000e0001"
    cut = display_text("x" * 5000, 100)
    assert cut == "x" * 100 + "... (4900 more characters)"
    assert display_text("x" * 100, 100) == "x" * 100  # the control: at the limit, kept whole


def test_bounded_keeps_head_and_tail_around_a_mark_that_counts_the_cut() -> None:
    text = "".join(chr(ord("a") + i % 26) for i in range(1000))
    assert bounded(text, 1000) == text  # the control: at the limit, kept whole
    assert bounded(text, 100) == f"{text[:50]}\n[... 900 characters cut ...]\n{text[-50:]}"
    assert bounded(text, 100, mark=" [...] ") == f"{text[:50]} [...] {text[-50:]}"
    assert bounded(text, 32, head=16, tail=15, mark="-") == f"{text[:16]}-{text[-15:]}"
    assert bounded(text, 10, head=10, tail=0, mark="+{cut}") == f"{text[:10]}+990"


@pytest.mark.parametrize("size", [1, 7, 64, 999])
def test_bounded_text_streamed_in_pieces_keeps_what_bounded_keeps(size: int) -> None:
    text = "".join(chr(ord("a") + i % 26) for i in range(1000))
    streamed = BoundedText(100)
    for start in range(0, len(text), size):
        streamed.add(text[start : start + size])
    assert streamed.value() == bounded(text, 100)
    assert streamed.cut == 900


@pytest.mark.parametrize(
    "text",
    [
        "plain",  # the control: nothing to escape
        'a "quoted" back\\slash',
        "tab\tnewline\nnul\x00escape\x1b",  # every control: JSON forbids them raw
        "caf\u00e9 \u2713",
        os.fsdecode(b"caf\xe9"),  # an undecodable byte: a lone surrogate
        "\ud800 alone",
        "past U+FFFF: \U0001f600",
    ],
)
@pytest.mark.parametrize("ascii_only", [False, True])
def test_json_string_is_a_json_literal_that_reads_back_as_the_text(
    text: str, ascii_only: bool
) -> None:
    """What a runner writes without ``json`` is read back by ``json`` as the very text."""
    literal = json_string(text, ascii_only)
    assert json.loads(literal) == text
    literal.encode()  # never refused: no surrogate is left raw
    assert literal.isascii() or not ascii_only, literal


def test_json_string_keeps_printable_characters_as_they_are() -> None:
    assert json_string("caf\u00e9 \u2713") == '"caf\u00e9 \u2713"'
    assert json_string('say "hi"\n') == '"say \\"hi\\"\\u000a"'


@pytest.mark.parametrize(
    "words",
    [
        [],
        ["true"],
        [""],
        ["sh", "-c", "echo 'a b' > out; exit 3"],
        ["path/with_under-score.py", "--key=value,1:2@host%x+y"],
        ["tab\there", "new\nline", "dollar$HOME", "star*", "back\\slash", '"quoted"'],
        ["é-not-ascii", "\udce9-undecodable", "a'b'c"],
    ],
)
def test_shell_join_quotes_as_shlex_does(words: list[str]) -> None:
    """The control is shlex itself: the same line for every kind of word."""
    assert shell_join(words) == shlex.join(words)
