r"""``xunit.xml_text``: text that XML 1.0 can carry, for the reader and the writer alike.

Colour codes are dropped, every other character XML forbids is shown as ``\xNN``-style
text, U+FFFD too (xunit-viewer cannot take it); names become one bounded, non-empty line.
A test may print anything, and the tail of its output goes into the result file's
``<failure>``: long text is capped keeping its head and tail around a marked cut, and each
case is round tripped through lxml, as the result file is written and read.
"""

from __future__ import annotations

import pytest
from lxml import etree

from ros_isolated_test.text import cut_mark
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT, legal, name_token, xml_safe


def test_legal_follows_the_xml_1_0_char_production() -> None:
    allowed = [0x9, 0xA, 0xD, 0x20, 0xD7FF, 0xE000, 0xFFFD, 0x10000, 0x10FFFF]
    forbidden = [0x0, 0x8, 0xB, 0x1F, 0xD800, 0xDFFF, 0xFFFE, 0xFFFF, 0x110000]
    assert all(legal(code) for code in allowed)
    assert not any(legal(code) for code in forbidden)


def test_colour_codes_are_dropped() -> None:
    assert xml_safe("\x1b[1;31mred\x1b[0m and \x1b[2Kplain") == "red and plain"


def test_forbidden_characters_are_shown_and_allowed_ones_kept() -> None:
    assert xml_safe("a\x00b\x07c\x1b") == "a\\x00b\\x07c\\x1b"
    assert xml_safe("\ud800 \ufffe \uffff \ufffd") == "\\ud800 \\ufffe \\uffff \\ufffd"
    kept = "tab\tline\ncr\r é ☃ \U0001f600 \ud7ff \ue000"
    assert xml_safe(kept) == kept


def test_whatever_comes_in_an_xml_parser_takes() -> None:
    """Every code point below U+11000 at once: the output is a text lxml accepts as is."""
    text = "".join(map(chr, range(0x11000)))
    safe = xml_safe(text)
    assert all(legal(ord(char)) for char in safe) and "\ufffd" not in safe
    element = etree.fromstring(f"<t>{safe.replace('&', '&amp;').replace('<', '&lt;')}</t>")
    assert element.text == safe.replace("\r", "\n")  # XML's own line-end handling
    assert not all(legal(ord(char)) for char in text), "the control: the input was not"


def test_a_limit_keeps_head_and_tail_around_a_marked_cut() -> None:
    text = "h" * TEXT_LIMIT + "t" * TEXT_LIMIT
    half = TEXT_LIMIT // 2
    expected = "h" * half + cut_mark(TEXT_LIMIT) + "t" * half
    assert xml_safe(text, TEXT_LIMIT) == expected
    assert xml_safe(text) == text, "no limit: nothing cut"
    assert xml_safe("short", TEXT_LIMIT) == "short"


def test_a_name_is_one_trimmed_line() -> None:
    assert name_token("  test\n\tname\r\n  two ", "default") == "test name two"
    assert name_token("\x1b[32mok\x1b[0m\x00", "default") == "ok\\x00"


def test_an_empty_name_takes_the_default() -> None:
    assert name_token(" \n\t ", "unnamed") == "unnamed"
    assert name_token("\x1b[0m", "unnamed") == "unnamed"
    assert name_token("x", "unnamed") == "x"


def test_a_long_name_is_bounded() -> None:
    assert name_token("n" * 40, "d", limit=10) == "nnnnn [...] nnnnn"
    assert name_token("n" * 10, "d", limit=10) == "n" * 10
    assert name_token("n" * 2000, "d") == "n" * 256 + " [...] " + "n" * 256


# --- what a result file can carry of a test's captured output --------------------------------


def _embeds(text: str) -> str:
    """Round-trip ``text`` through an lxml element and a parse, as a result file does."""
    element = etree.Element("failure", message=text)
    element.text = text
    parsed = etree.fromstring(etree.tostring(element))
    assert parsed.get("message") == text
    return parsed.text or ""


def test_xml_safe_drops_ansi_codes_and_shows_other_illegal_characters() -> None:
    raw = "\x1b[1;31mred\x1b[0m nul\x00 bell\x07 vt\x0b lone-esc\x1b| ff\x0c surrogate\ud800 ok"
    with pytest.raises(ValueError):
        _embeds(raw)
    safe = xml_safe(raw)
    assert safe == "red nul\\x00 bell\\x07 vt\\x0b lone-esc\\x1b| ff\\x0c surrogate\\ud800 ok"
    assert _embeds(safe) == safe


def test_xml_safe_keeps_legal_text_as_it_is() -> None:
    text = "tab\tnewline\nreturn\r <&>\"' ünïcode 漢字 \U0001f916 \u0085 \x7f"
    assert xml_safe(text) == text


def test_xml_safe_shows_the_replacement_character() -> None:
    """Legal XML, but xunit-viewer takes a file holding U+FFFD for CP1252 and aborts."""
    assert xml_safe("a\ufffdb") == "a\\ufffdb"


def test_xml_safe_caps_long_text_keeping_head_and_tail() -> None:
    text = "HEAD" + "m" * 992 + "TAIL"
    safe = xml_safe(text, limit=100)
    assert safe.startswith("HEAD" + "m" * 46 + "\n")
    assert safe.endswith("\n" + "m" * 46 + "TAIL")
    assert "\n[... 900 characters cut ...]\n" in safe
    assert len(safe) < 100 + len("\n[... 900 characters cut ...]\n") + 1


def test_xml_safe_cap_counts_characters_after_cleaning() -> None:
    text = "\x1b[31m" * 1000 + "short"
    assert xml_safe(text, limit=100) == "short"


def test_xml_safe_at_the_limit_is_not_cut() -> None:
    text = "x" * 100
    assert xml_safe(text, limit=100) == text
