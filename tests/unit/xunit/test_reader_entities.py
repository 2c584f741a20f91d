"""The reader as a whole on a DOCTYPE's entities: expanded by libxml2, bounded, nothing loaded.

The sanitiser passes a short, readable DOCTYPE to the parser of ``safe_parser``, which
expands internal entities and loads nothing else; the builder counts what they add.
Here the whole reader: an entity's markup is read as markup, as any XML reader does;
an external entity stays undefined beside an internal one; a bomb, a long chain or a
loop of entities is stopped and said, keeping what came before; a declaration hidden
in other markup defines nothing; the predefined entities cannot be redefined. Each is
checked with a control that the same construction used sensibly is read.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from helpers import peak_rss
from helpers.canonical import Canonical
from helpers.xunit import (
    BOMBS,
    DECLARATION,
    MB,
    billion_laughs,
    canonical_of,
    quadratic_blowup,
    read_text,
    repairs,
    suite_xml,
    with_doctype,
)

from ros_isolated_test.xunit import reader, sanitiser

#: Peak RSS allowed for a child that reads a bomb; an interpreter with lxml takes about
#: 20 MB.
MAX_RSS = 100 * MB


_READ_IN_CHILD = """
import json, sys
from pathlib import Path
from ros_isolated_test.xunit import reader
read = reader.read(Path(sys.argv[1]))
print(json.dumps({
    "cases": [[case.attrs.get("name"), case.complete, case.system_out[:10]] for case in read.cases],
    "problems": read.problems,
}))
"""


def _bomb_file(bomb: str, references: int = 50_000) -> str:
    # An entity of 50 kB: the DOCTYPE is within sanitiser.DOCTYPE_LIMIT, so it is expanded.
    body = {"billion-laughs": "&lol9;", "quadratic-blowup": "&big;" * references}[bomb]
    doctype = (billion_laughs(10) if bomb == "billion-laughs" else quadratic_blowup(1)).split(
        "<r>"
    )[0]
    return (
        f'{DECLARATION}{doctype}<testsuite name="s"><testcase name="a"/>'
        f'<testcase name="bomb"><system-out>{body}</system-out></testcase></testsuite>'
    )


@pytest.mark.parametrize("bomb", sorted(BOMBS))
def test_the_reader_stops_an_entity_bomb_and_says_so(tmp_path: Path, bomb: str) -> None:
    """libxml2 2.11 and later refuse it; before, the reader's own count stops it."""
    source = tmp_path / "bomb.xml"
    source.write_text(_bomb_file(bomb))
    out = tmp_path / "child.json"
    peak = peak_rss.measure([sys.executable, "-c", _READ_IN_CHILD, str(source)], stdout=out)
    assert peak.returncode == 0 and not peak.timed_out
    assert peak.max_rss < MAX_RSS
    read = json.loads(out.read_text())
    assert [case[:2] for case in read["cases"]] == [["a", True], ["bomb", False]]
    [problem] = read["problems"]
    assert "(an entity bomb?): reading stopped there" in problem


def test_control_the_reader_expands_the_same_entity_used_a_few_times(tmp_path: Path) -> None:
    source = tmp_path / "few.xml"
    source.write_text(_bomb_file("quadratic-blowup", references=3))
    read = reader.read(source)
    assert read.problems == []
    assert read.cases[1].system_out.startswith("B" * 1000)


# --- an entity's markup is markup ------------------------------------------------------------


def test_an_entitys_markup_is_read_as_markup(tmp_path: Path) -> None:
    """What changed: the hand-written expansion kept "<b>" as text; libxml2 reads markup."""
    subset = '<!ENTITY why "<b>expected</b> 1"><!ENTITY cases "<testcase name=\'from-entity\'/>">'
    read = read_text(tmp_path, with_doctype(subset, '<failure message="m">got &why;</failure>'))
    assert read.cases[1].outcomes[0].text == "got expected 1"
    read = read_text(
        tmp_path,
        with_doctype(subset, "").replace('<testcase name="a"/>', '<testcase name="a"/>&cases;'),
    )
    assert [case.attrs["name"] for case in read.cases] == ["a", "from-entity", "t"]


def test_control_markup_escaped_in_the_entity_is_text(tmp_path: Path) -> None:
    subset = '<!ENTITY why "&#38;lt;b>expected&#38;lt;/b> 1">'
    read = read_text(tmp_path, with_doctype(subset, '<failure message="&why;">&why;</failure>'))
    assert read.problems == []
    outcome = read.cases[1].outcomes[0]
    assert (outcome.attrs["message"], outcome.text) == ("<b>expected</b> 1", "<b>expected</b> 1")


def test_an_entity_with_markup_in_an_attribute_value_is_damage(tmp_path: Path) -> None:
    """XML forbids "<" in an attribute value, from an entity too; the case before is kept."""
    subset = '<!ENTITY why "<b>expected</b> 1">'
    read = read_text(tmp_path, with_doctype(subset, '<failure message="&why;">t</failure>'))
    assert [(case.attrs["name"], case.complete) for case in read.cases] == [
        ("a", True),
        ("t", False),
    ]
    [problem] = read.problems
    assert "'<' in entity 'why' is not allowed in attributes values" in problem


# --- a DOCTYPE with small internal entities, made canonical -------------------------------


ENTITIES = """<!DOCTYPE testsuites [
  <!-- <!ENTITY why "a commented-out declaration defines nothing"> -->
  <!ENTITY why "expected 1, got 2">
  <!ENTITY why "a second declaration of a name is ignored">
  <!ENTITY where 'in &quot;&cls;&quot; (&#x41;&#66;)'>
  <!ENTITY cls "TestTalker">
  <!ENTITY markup "<b>bold</b> &amp; &lt;tag&gt;">
]>
"""


def test_internal_entities_are_expanded_and_counts_stay_right(tmp_path: Path) -> None:
    """libxml2 expands them; an entity's markup is read as markup, as any XML reader does."""
    data = suite_xml(
        '<testcase classname="&cls;" name="ok"/>'
        '<testcase classname="&cls;" name="t"><failure message="boom: &why;">'
        "Traceback &where;: &why; &amp; more &markup;</failure></testcase>",
        attrs=' tests="2" failures="1" errors="0"',
        head=DECLARATION + ENTITIES,
    )
    result, _ = canonical_of(tmp_path, data)
    assert result.counts == (2, 1, 0, 0)
    failed = result.case("t", "pkg.TestTalker")
    assert failed.outcome == "failure"
    assert failed.message == "boom: expected 1, got 2"
    assert failed.text == 'Traceback in "TestTalker" (AB): expected 1, got 2 & more bold & <tag>'
    assert repairs(result) == sanitiser.DOCTYPE_REMOVED


def test_external_entity_stays_undefined_beside_an_internal_one(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET-4711\n")
    head = f'{DECLARATION}<!DOCTYPE x [<!ENTITY why "small"><!ENTITY e SYSTEM "file://{secret}">]>'
    data = suite_xml(
        '<testcase classname="C" name="a"><failure message="&why;">&why;</failure></testcase>'
        '<testcase classname="C" name="b"><system-out>&e;</system-out></testcase>',
        head=head,
    )
    result, rendered = canonical_of(tmp_path, data)
    assert b"TOP-SECRET" not in rendered
    assert result.case("a").message == "small"
    damage = result.case("result file")
    assert damage.outcome == "error"
    assert "Entity 'e' not defined" in damage.message


def test_entity_expansion_is_bounded_in_total(tmp_path: Path) -> None:
    """Each expansion is small, but 2000 of them would be 8 MB: the expansion bound stops them.

    libxml2 2.11 and later stop it themselves, the reader's count does before.
    """
    value = "x" * 4000
    references = "&four;" * 2000
    data = suite_xml(
        f'<testcase classname="C" name="a"/><testcase classname="C" name="b">'
        f"<system-out>{references}</system-out></testcase>",
        head=f'{DECLARATION}<!DOCTYPE x [<!ENTITY four "{value}">]>',
    )
    result, rendered = canonical_of(tmp_path, data)
    assert len(rendered) < 200_000
    assert result.case("a").outcome == "passed"
    assert "(an entity bomb?)" in result.case("result file").message


def test_control_a_few_of_those_expansions_are_read_whole(tmp_path: Path) -> None:
    value = "x" * 4000
    data = suite_xml(
        '<testcase classname="C" name="b"><failure message="m">'
        + "&four;" * 3
        + "</failure></testcase>",
        head=f'{DECLARATION}<!DOCTYPE x [<!ENTITY four "{value}">]>',
    )
    result, _ = canonical_of(tmp_path, data)
    assert result.counts == (1, 1, 0, 0)
    assert result.case("b").text == value * 3


def test_entity_reference_cut_by_a_chunk_boundary_is_expanded(tmp_path: Path) -> None:
    head = f'{DECLARATION}<!DOCTYPE x [<!ENTITY why "expected 1, got 2">]>'
    opening = head + '<testsuites><testsuite name="s"><testcase classname="C" name="t">'
    opening += '<failure message="m">'
    # Put "&why;" across the first chunk's end, one character in.
    filler = "f" * (reader.CHUNK_BYTES - len(opening.encode()) - 1)
    data = opening + filler + "&why;</failure></testcase></testsuite></testsuites>"
    assert data.encode()[reader.CHUNK_BYTES - 1 : reader.CHUNK_BYTES + 4] == b"&why;"
    result, _ = canonical_of(tmp_path, data)
    assert result.counts == (1, 1, 0, 0)
    assert result.case("t").text.endswith("expected 1, got 2")


def _entity_case(tmp_path: Path, subset: str, message: str) -> Canonical:
    head = f"{DECLARATION}<!DOCTYPE x [{subset}]>"
    data = suite_xml(
        f'<testcase classname="C" name="a"><failure message="{message}">t</failure></testcase>',
        head=head,
    )
    return canonical_of(tmp_path, data)[0]


HIDING_PLACES = {
    "parameter entity": "<!ENTITY % pe \"<!ENTITY hidden 'H'>\">",
    "another entity's literal": "<!ENTITY outer \"<!ENTITY hidden 'H'>\">",
    "processing instruction": "<?pi <!ENTITY hidden 'H'> ?>",
    "comment": "<!-- <!ENTITY hidden 'H'> -->",
}


@pytest.mark.parametrize("place", sorted(HIDING_PLACES))
def test_a_declaration_inside_other_markup_defines_nothing(tmp_path: Path, place: str) -> None:
    subset = HIDING_PLACES[place] + '<!ENTITY shown "S">'
    # Control: the top-level declaration beside it is read.
    assert _entity_case(tmp_path, subset, "&shown;").case("a").message == "S"
    hidden = _entity_case(tmp_path, subset, "&hidden;")
    assert "Entity 'hidden' not defined" in hidden.case("result file").message


def test_an_entity_whose_literal_holds_a_declaration_is_damage_in_an_attribute(
    tmp_path: Path,
) -> None:
    """XML forbids "<" in an attribute value, from an entity too (``test_reader_entities``)."""
    subset = "<!ENTITY outer \"<!ENTITY hidden 'H'>\">"
    damage = _entity_case(tmp_path, subset, "&outer;").case("result file").message
    assert "'<' in entity 'outer' is not allowed in attributes values" in damage


def test_the_predefined_entities_are_never_redefined(tmp_path: Path) -> None:
    subset = "".join(f'<!ENTITY {name} "X">' for name in ("lt", "gt", "amp", "quot", "apos"))
    subset += '<!ENTITY mine "M">'
    message = "a &lt; b &gt; c &amp; &quot;d&quot; &apos;e&apos; &mine;"
    result = _entity_case(tmp_path, subset, message)
    assert result.case("a").message == "a < b > c & \"d\" 'e' M"


def test_deeply_nested_entities_are_refused_not_fatal(tmp_path: Path) -> None:
    """A chain of 1000 entities: libxml2 refuses it, and the file is read up to its use."""
    chain = "".join(f'<!ENTITY e{i} "&e{i + 1};">' for i in range(1000))
    head = f'{DECLARATION}<!DOCTYPE x [{chain}<!ENTITY e1000 "end">]>'
    data = suite_xml(
        '<testcase classname="C" name="a"><system-out>&e0;</system-out></testcase>', head=head
    )
    result, _ = canonical_of(tmp_path, data)
    assert "(an entity bomb?)" in result.case("result file").message


def test_recursive_entity_is_refused(tmp_path: Path) -> None:
    head = f'{DECLARATION}<!DOCTYPE x [<!ENTITY r "a&r;"><!ENTITY ok "fine">]>'
    data = suite_xml(
        '<testcase classname="C" name="a"><failure message="&ok;">&r;</failure></testcase>',
        head=head,
    )
    result, _ = canonical_of(tmp_path, data)
    assert "entity reference loop" in result.case("result file").message
    assert result.case("a").message == "fine"
