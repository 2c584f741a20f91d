"""``xunit.sanitiser``: whatever the bytes, the parser gets clean UTF-8 and one readable DOCTYPE.

The first stage of reading: any encoding, bytes that are not text, characters XML
forbids (raw or as references), colour codes and DTD markup come out as text any XML
1.0 parser takes, each repair said. The prolog is defused: the first DOCTYPE reaches
the parser only when it ends within ``DOCTYPE_LIMIT`` characters and the parser can
read it (else only a use of its entities is damage), and DTD markup after the root
element started is made inert. A chunk boundary cuts no reference, keyword or DOCTYPE,
and the parser's line numbers stay the file's.
"""

from __future__ import annotations

import itertools
from pathlib import Path

from helpers.xunit import DECLARATION, read_text, with_doctype

from ros_isolated_test.text import shown_code
from ros_isolated_test.xunit import raw, reader, sanitiser, xml_text
from ros_isolated_test.xunit.sanitiser import Sanitiser


def sanitised(*chunks: bytes) -> tuple[str, raw.ReadResult]:
    """What the parser gets of ``chunks`` fed in turn (the last one final), and the repairs."""
    result = raw.ReadResult(Path("t.xml"))
    stream = Sanitiser(result)
    out = b"".join(
        stream.feed(chunk, final=index == len(chunks) - 1) for index, chunk in enumerate(chunks)
    )
    stream.finish()
    return out.decode("utf-8"), result


# --- bytes that are not XML made safe ------------------------------------------------------


def test_bytes_that_are_not_text_are_shown_never_replaced_and_counted() -> None:
    r"""U+FFFD would make xunit-viewer guess the file is CP1252 and abort: ``\xff`` instead."""
    text, result = sanitised(b"<r>a\xffb\xfe</r>")
    assert text == "<r>a\\xffb\\xfe</r>"
    assert result.repairs == ["2 byte(s) that were not valid text were written as \\xNN"]
    text, result = sanitised("<r>é ☃</r>".encode())  # the control: valid UTF-8 as it is
    assert (text, result.repairs) == ("<r>é ☃</r>", [])


def test_characters_xml_forbids_are_shown_and_colour_codes_dropped() -> None:
    text, result = sanitised(b"<r>\x01\x1b[31mred\x1b[0m \xef\xbf\xbd</r>")
    assert text == "<r>\\x01red \\ufffd</r>"
    assert result.repairs == ["2 character(s) that XML 1.0 forbids were written as \\xNN"]


def test_the_declared_encoding_is_read_and_a_codec_that_is_no_encoding_is_not() -> None:
    latin = '<?xml version="1.0" encoding="ISO-8859-1"?><r>é</r>'.encode("latin-1")
    text, result = sanitised(latin)
    assert (text, result.repairs) == ("<r>é</r>", [])
    assert sanitised("<r>é</r>".encode("utf-16"))[0] == "<r>é</r>"  # by its BOM
    for name in ("hex", "rot13", "nonesuch"):
        declared = f'<?xml version="1.0" encoding="{name}"?><r>x</r>'.encode()
        text, result = sanitised(declared)
        assert text == "<r>x</r>"
        assert result.repairs == [f"unknown encoding {name!r} declared; read as UTF-8"]


def test_dtd_markup_after_the_root_started_is_made_inert() -> None:
    text, result = sanitised(b'<r><!ENTITY x "y"><!DOCTYPE q></r>')
    assert text == '<r>&lt;!ENTITY x "y">&lt;!DOCTYPE q></r>'
    assert result.repairs == [
        "DTD markup after the root element started was made inert: it declares nothing "
        "and loads nothing"
    ]
    text, result = sanitised(b"<r><![CDATA[x]]></r>")  # the control: other <! markup stays
    assert (text, result.repairs) == ("<r><![CDATA[x]]></r>", [])


def test_a_chunk_boundary_cuts_no_reference_and_no_colour_code() -> None:
    whole = sanitised(b"<r>&#x1;\x1b[31mred</r>")
    assert whole[0] == "<r>\\x01red</r>"
    for cut in range(4, len(b"<r>&#x1;\x1b[31m")):
        data = b"<r>&#x1;\x1b[31mred</r>"
        assert sanitised(data[:cut], data[cut:]) == whole, cut


def test_the_prolog_keeps_only_its_line_breaks() -> None:
    """Declaration, comments and processing instructions go; the root stays on its line."""
    text, result = sanitised(b"<?xml version='1.0'?>\n<!-- c\n -->\n<?pi x?>\n<r/>")
    assert (text, result.repairs) == ("\n\n\n\n<r/>", [])


# --- character references: illegal ones shown, legal ones passed (most without a check) ------


def _references(codes: range | tuple[int, ...], form: str) -> list[tuple[str, int]]:
    return [(form.format(code), code) for code in codes]


def test_every_character_reference_is_shown_exactly_when_xml_forbids_it() -> None:
    """All code points, decimal and hex, some zero-padded: the fast path skips no bad one.

    In blocks: a test's peak memory is charged to every child pytest forks after it.
    """
    padded = (0, 8, 31, 32, 65, 9999, 10000, 49999, 50000, 0xD7FF, 0xD800, 0xFFFE)
    blocks = itertools.chain(
        (
            _references(range(first, min(first + 0x10000, 0x110002)), form)
            for first in range(0, 0x110002, 0x10000)
            for form in ("&#{};", "&#x{:x};")
        ),
        [_references(padded, "&#000{};") + _references(padded, "&#x00{:X};")],
    )
    for refs in blocks:  # one block at a time
        sanitiser = Sanitiser(raw.ReadResult(Path("refs.xml")))
        body = "|".join(ref for ref, _code in refs)
        out = sanitiser.feed(f"<r>{body}</r>".encode(), final=True).decode()
        shown = out[len("<r>") : -len("</r>")].split("|")
        expected = [
            ref if xml_text.legal(code) and code != 0xFFFD else shown_code(code)
            for ref, code in refs
        ]
        assert shown == expected


# --- the DOCTYPE: kept whole when short and readable, else dropped ------------------------


def _padded(size: int) -> str:
    """An internal subset of ``size`` characters, most of it one comment."""
    entity = '<!ENTITY why "expected 1">'
    return entity + "<!--" + "p" * (size - len(entity) - 7) + "-->"


def _doctype_of(subset_size: int) -> str:
    head = "<!DOCTYPE testsuite []>"
    return with_doctype(_padded(subset_size - len(head)), '<failure message="&why;">t</failure>')


def test_a_doctype_over_the_limit_is_dropped_and_its_entities_undefined(tmp_path: Path) -> None:
    read = read_text(tmp_path, _doctype_of(sanitiser.DOCTYPE_LIMIT + 1))
    assert read.repairs == [
        sanitiser.DOCTYPE_REMOVED,
        f"the DOCTYPE does not end within {sanitiser.DOCTYPE_LIMIT} characters: "
        "its entities are not defined",
    ]
    [problem] = read.problems
    assert "Entity 'why' not defined" in problem


def test_control_a_doctype_at_the_limit_is_read(tmp_path: Path) -> None:
    read = read_text(tmp_path, _doctype_of(sanitiser.DOCTYPE_LIMIT))
    assert (read.problems, read.repairs) == ([], [sanitiser.DOCTYPE_REMOVED])
    assert read.cases[1].outcomes[0].attrs["message"] == "expected 1"


def test_a_doctype_the_parser_cannot_read_is_dropped_not_fatal(tmp_path: Path) -> None:
    """Only a use of its entities is damage: every case that uses none is read."""
    broken = '<!ENTITY why "expected 1"><!ELEMENT>'
    read = read_text(tmp_path, with_doctype(broken, '<failure message="m">t</failure>'))
    assert read.problems == []
    assert [case.attrs["name"] for case in read.cases] == ["a", "t"]
    assert read.repairs[0] == sanitiser.DOCTYPE_REMOVED
    assert read.repairs[1].startswith("a DOCTYPE the parser cannot read (")
    assert read.repairs[1].endswith(") was dropped: its entities are not defined")


def test_control_the_same_doctype_well_formed_is_read(tmp_path: Path) -> None:
    subset = '<!ENTITY why "expected 1"><!ELEMENT testsuite ANY>'
    read = read_text(tmp_path, with_doctype(subset, '<failure message="&why;">t</failure>'))
    assert (read.problems, read.repairs) == ([], [sanitiser.DOCTYPE_REMOVED])
    assert read.cases[1].outcomes[0].attrs["message"] == "expected 1"


def test_a_doctype_cut_by_a_chunk_boundary_reaches_the_parser_whole(tmp_path: Path) -> None:
    """The first chunk ends 200 characters into an entity's value: no markup to hold back."""
    why = "expected 1, " + "." * 400
    comment = "<!--" + "c" * (reader.CHUNK_BYTES - len(DECLARATION) - 250) + "-->"
    text = with_doctype(
        f'<!ENTITY why "{why}">',
        '<failure message="&why;">&why;</failure>',
        DECLARATION + comment,
    )
    assert text.index("<!DOCTYPE") < reader.CHUNK_BYTES - 200
    assert "<" not in text[reader.CHUNK_BYTES - 200 : reader.CHUNK_BYTES + 100]
    read = read_text(tmp_path, text)
    assert (read.problems, read.repairs) == ([], [sanitiser.DOCTYPE_REMOVED])
    assert read.cases[1].outcomes[0].text == why


def test_lines_around_the_doctype_keep_their_numbers(tmp_path: Path) -> None:
    """The parser sees the DOCTYPE at its own line; what else the prolog held, as breaks."""
    prolog = f"{DECLARATION}<!-- one\ntwo -->\n<?pi three?>\n"
    text = with_doctype("\n<!ENTITY why 'w'>\n", "\n\n<failure message='&why;'>", prolog)
    assert text.count("\n", 0, text.index("<failure")) == 9
    read = read_text(tmp_path, text)
    [problem] = read.problems
    assert "cut off or broken at line 10 " in problem
