"""A DOCTYPE's entities are libxml2's to expand, with parser settings that are safe alone.

The reader passes a result file's DOCTYPE to the parser (``reader.new_parser``), which
expands internal entities and loads nothing else. So the parser is tested here on its
own, bypassing every sanitiser step: an external entity is never read, a URL never
fetched, and an entity bomb is refused in bounded memory; each with a control showing
that the same document does name a readable file, a reachable server, a real expansion.
Then the reader around it: what it passes on of the prolog, what it reports, and what
reads differently now that an entity's markup is markup.
"""

from __future__ import annotations

import contextlib
import http.client
import json
import sys
import urllib.request
from pathlib import Path

import pytest
from helpers import peak_rss
from helpers.listener import Listener
from lxml import etree

from ros_isolated_test.xunit import reader

MB = 1000 * 1000
#: Peak RSS allowed for a child that parses or reads a bomb; an interpreter with lxml
#: takes about 20 MB.
MAX_RSS = 100 * MB
TOKEN = "SECRET-TOKEN-0x5eed"
DECLARATION = '<?xml version="1.0" encoding="UTF-8"?>\n'


class Recorder:
    """A parser target that keeps everything the parser reports, as the reader's would."""

    def __init__(self) -> None:
        self.seen: list[str] = []

    def start(self, tag: str, attrib: dict[str, str]) -> None:
        self.seen += [tag, *attrib.keys(), *attrib.values()]

    def end(self, tag: str) -> None:
        return None

    def data(self, data: str) -> None:
        self.seen.append(data)

    def comment(self, text: str) -> None:
        self.seen.append(text)

    def close(self) -> str:
        return "".join(self.seen)


def parse_with_factory(document: str) -> str:
    """All the factory's parser reports of ``document``, its error message included."""
    target = Recorder()
    parser = reader.new_parser(target)
    try:
        parser.feed(document.encode())
        parser.close()
    except etree.XMLSyntaxError as error:
        target.seen.append(f"error: {error}")
    return target.close()


# --- no local file is read ----------------------------------------------------------------


def _file_documents(tmp_path: Path) -> dict[str, str]:
    """Each way XML can name a local file, all leading to TOKEN."""
    secret = tmp_path / "secret.txt"
    secret.write_text(TOKEN)
    dtd = tmp_path / "entities.dtd"
    dtd.write_text(f'<!ENTITY q "{TOKEN}">')
    return {
        "general-entity": f'<!DOCTYPE r [<!ENTITY e SYSTEM "file://{secret}">]><r>&e;</r>',
        "parameter-entity": f'<!DOCTYPE r [<!ENTITY % p SYSTEM "file://{dtd}"> %p;]><r>&q;</r>',
        "parameter-entity-plain-path": f'<!DOCTYPE r [<!ENTITY % p SYSTEM "{dtd}"> %p;]><r>&q;</r>',
        "external-dtd": f'<!DOCTYPE r SYSTEM "file://{dtd}"><r>&q;</r>',
    }


FILE_FORMS = ["general-entity", "parameter-entity", "parameter-entity-plain-path", "external-dtd"]


@pytest.mark.parametrize("form", FILE_FORMS)
def test_the_parser_never_reads_a_local_file(tmp_path: Path, form: str) -> None:
    """lxml 5.2.1 with 'internal' alone still reads the parameter entity: the resolver doesn't."""
    reported = parse_with_factory(_file_documents(tmp_path)[form])
    assert TOKEN not in reported


@pytest.mark.parametrize("form", FILE_FORMS)
def test_control_a_parser_that_loads_reads_the_file(tmp_path: Path, form: str) -> None:
    loading = etree.XMLParser(load_dtd=True, resolve_entities=True, no_network=True)
    root = etree.fromstring(_file_documents(tmp_path)[form].encode(), loading)
    assert root.text == TOKEN


# --- no URL is fetched --------------------------------------------------------------------

URL_FORMS = {
    "general-entity": '<!DOCTYPE r [<!ENTITY e SYSTEM "{url}e.txt">]><r>&e;</r>',
    "parameter-entity": '<!DOCTYPE r [<!ENTITY % p SYSTEM "{url}p.dtd"> %p;]><r/>',
    "external-dtd": '<!DOCTYPE r SYSTEM "{url}r.dtd"><r/>',
}


@pytest.mark.parametrize("form", sorted(URL_FORMS))
def test_the_parser_never_contacts_a_server(form: str) -> None:
    with contextlib.closing(Listener()) as listener:
        parse_with_factory(URL_FORMS[form].format(url=listener.url))
        assert listener.connections() == []


@pytest.mark.parametrize("form", sorted(URL_FORMS))
def test_control_the_server_sees_a_fetch_of_that_url(form: str) -> None:
    with contextlib.closing(Listener()) as listener:
        url = URL_FORMS[form].format(url=listener.url).split('"')[1]
        # No proxy from the environment; the listener closes without answering, so the
        # fetch fails, after connecting.
        opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
        with contextlib.suppress(OSError, http.client.HTTPException):
            opener.open(url, timeout=30).close()
        assert len(listener.connections()) == 1


# --- entity bombs -------------------------------------------------------------------------


def billion_laughs(levels: int) -> str:
    """``levels`` entities, each ten of the one before: 3 * 10**(levels - 1) characters."""
    entities = '<!ENTITY lol0 "lol">' + "".join(
        f'<!ENTITY lol{level} "{f"&lol{level - 1};" * 10}">' for level in range(1, levels)
    )
    return f"<!DOCTYPE r [{entities}]><r>&lol{levels - 1};</r>"


def quadratic_blowup(references: int, size: int = 50_000) -> str:
    """One ``size``-character entity, referenced ``references`` times."""
    return f'<!DOCTYPE r [<!ENTITY big "{"B" * size}">]><r>{"&big;" * references}</r>'


#: Expanded, each is 3 GB and 2.5 GB; on disk 1 kB and 300 kB.
BOMBS = {"billion-laughs": billion_laughs(10), "quadratic-blowup": quadratic_blowup(50_000)}
#: The same constructions, small: expanded whole by the same parser (libxml2 2.9 takes
#: three levels of ten for a loop already).
SMALL = {
    "billion-laughs": (billion_laughs(2), "lol" * 10),
    "quadratic-blowup": (quadratic_blowup(5, size=1000), "B" * 5000),
}

_PARSE_IN_CHILD = """
import json, sys
from pathlib import Path
from lxml import etree
from ros_isolated_test.xunit import reader
try:
    root = etree.fromstring(Path(sys.argv[1]).read_bytes(), reader.new_parser())
    print(json.dumps({"refused": None, "text": len(root.text or "")}))
except etree.XMLSyntaxError as error:
    print(json.dumps({"refused": str(error), "text": 0}))
"""


@pytest.mark.parametrize("bomb", sorted(BOMBS))
def test_the_parser_refuses_an_entity_bomb_in_bounded_memory(tmp_path: Path, bomb: str) -> None:
    """Built as a tree, whatever the parser expands it holds: it expands next to nothing."""
    source = tmp_path / "bomb.xml"
    source.write_text(BOMBS[bomb])
    out = tmp_path / "child.json"
    peak = peak_rss.measure([sys.executable, "-c", _PARSE_IN_CHILD, str(source)], stdout=out)
    assert peak.returncode == 0 and not peak.timed_out
    print(f"{bomb}: peak RSS {peak.max_rss / MB:.0f} MB")
    assert peak.max_rss < MAX_RSS
    assert json.loads(out.read_text())["refused"]


@pytest.mark.parametrize("bomb", sorted(SMALL))
def test_control_the_same_construction_small_is_expanded_whole(bomb: str) -> None:
    document, expanded = SMALL[bomb]
    assert etree.fromstring(document.encode(), reader.new_parser()).text == expanded


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
    # An entity of 50 kB: the DOCTYPE is within reader.DOCTYPE_LIMIT, so it is expanded.
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


def _builder(fed: int) -> reader._Builder:
    builder = reader._Builder(reader.ReadResult(Path("t.xml")))
    builder.fed, builder.count_expansion = fed, True  # as once a DOCTYPE reached the parser
    builder.start("testsuite", {"name": "s"})
    return builder


def test_the_readers_count_stops_what_an_old_libxml2_would_stream() -> None:
    """libxml2 before 2.11 streams an expansion to the target without bound, in time.

    The reader's builder counts what the parser reports against what it was fed; driven
    here as that parser would drive it.
    """
    builder = _builder(fed=1000)
    builder.data("B" * reader.ENTITY_BUDGET)
    with pytest.raises(reader._Stop, match=r"over 5 times what the file holds"):
        builder.data("B" * 1000)
    # Beyond the budget, five times what was fed is allowed.
    builder = _builder(fed=10 * reader.ENTITY_BUDGET)
    builder.data("B" * 59 * reader.ENTITY_BUDGET)
    with pytest.raises(reader._Stop):
        builder.start("testcase", {"name": "B" * reader.ENTITY_BUDGET})


def test_control_what_was_fed_is_never_too_much() -> None:
    builder = _builder(fed=100 * reader.ENTITY_BUDGET)
    for _ in range(100):
        builder.data("B" * reader.ENTITY_BUDGET)
    assert builder.reported == 100 * reader.ENTITY_BUDGET + len("<testsuite>") + len("s")


# --- what the reader passes on of the prolog ------------------------------------------------


def read_text(tmp_path: Path, text: str) -> reader.ReadResult:
    source = tmp_path / "t.xml"
    source.write_text(text)
    return reader.read(source)


def _with_doctype(subset: str, body: str, prolog: str = DECLARATION) -> str:
    return (
        f'{prolog}<!DOCTYPE testsuite [{subset}]>\n<testsuite name="s">'
        f'<testcase name="a"/><testcase name="t">{body}</testcase></testsuite>'
    )


def test_an_entitys_markup_is_read_as_markup(tmp_path: Path) -> None:
    """What changed: the hand-written expansion kept "<b>" as text; libxml2 reads markup."""
    subset = '<!ENTITY why "<b>expected</b> 1"><!ENTITY cases "<testcase name=\'from-entity\'/>">'
    read = read_text(tmp_path, _with_doctype(subset, '<failure message="m">got &why;</failure>'))
    assert read.cases[1].outcomes[0].text == "got expected 1"
    read = read_text(
        tmp_path,
        _with_doctype(subset, "").replace('<testcase name="a"/>', '<testcase name="a"/>&cases;'),
    )
    assert [case.attrs["name"] for case in read.cases] == ["a", "from-entity", "t"]


def test_control_markup_escaped_in_the_entity_is_text(tmp_path: Path) -> None:
    subset = '<!ENTITY why "&#38;lt;b>expected&#38;lt;/b> 1">'
    read = read_text(tmp_path, _with_doctype(subset, '<failure message="&why;">&why;</failure>'))
    assert read.problems == []
    outcome = read.cases[1].outcomes[0]
    assert (outcome.attrs["message"], outcome.text) == ("<b>expected</b> 1", "<b>expected</b> 1")


def test_an_entity_with_markup_in_an_attribute_value_is_damage(tmp_path: Path) -> None:
    """XML forbids "<" in an attribute value, from an entity too; the case before is kept."""
    subset = '<!ENTITY why "<b>expected</b> 1">'
    read = read_text(tmp_path, _with_doctype(subset, '<failure message="&why;">t</failure>'))
    assert [(case.attrs["name"], case.complete) for case in read.cases] == [
        ("a", True),
        ("t", False),
    ]
    [problem] = read.problems
    assert "'<' in entity 'why' is not allowed in attributes values" in problem


def _padded(size: int) -> str:
    """An internal subset of ``size`` characters, most of it one comment."""
    entity = '<!ENTITY why "expected 1">'
    return entity + "<!--" + "p" * (size - len(entity) - 7) + "-->"


def _doctype_of(subset_size: int) -> str:
    head = "<!DOCTYPE testsuite []>"
    return _with_doctype(_padded(subset_size - len(head)), '<failure message="&why;">t</failure>')


def test_a_doctype_over_the_limit_is_dropped_and_its_entities_undefined(tmp_path: Path) -> None:
    read = read_text(tmp_path, _doctype_of(reader.DOCTYPE_LIMIT + 1))
    assert read.repairs == [
        reader.DOCTYPE_REMOVED,
        f"the DOCTYPE does not end within {reader.DOCTYPE_LIMIT} characters: "
        "its entities are not defined",
    ]
    [problem] = read.problems
    assert "Entity 'why' not defined" in problem


def test_control_a_doctype_at_the_limit_is_read(tmp_path: Path) -> None:
    read = read_text(tmp_path, _doctype_of(reader.DOCTYPE_LIMIT))
    assert (read.problems, read.repairs) == ([], [reader.DOCTYPE_REMOVED])
    assert read.cases[1].outcomes[0].attrs["message"] == "expected 1"


def test_a_doctype_the_parser_cannot_read_is_dropped_not_fatal(tmp_path: Path) -> None:
    """Only a use of its entities is damage: every case that uses none is read."""
    broken = '<!ENTITY why "expected 1"><!ELEMENT>'
    read = read_text(tmp_path, _with_doctype(broken, '<failure message="m">t</failure>'))
    assert read.problems == []
    assert [case.attrs["name"] for case in read.cases] == ["a", "t"]
    assert read.repairs[0] == reader.DOCTYPE_REMOVED
    assert read.repairs[1].startswith("a DOCTYPE the parser cannot read (")
    assert read.repairs[1].endswith(") was dropped: its entities are not defined")


def test_control_the_same_doctype_well_formed_is_read(tmp_path: Path) -> None:
    subset = '<!ENTITY why "expected 1"><!ELEMENT testsuite ANY>'
    read = read_text(tmp_path, _with_doctype(subset, '<failure message="&why;">t</failure>'))
    assert (read.problems, read.repairs) == ([], [reader.DOCTYPE_REMOVED])
    assert read.cases[1].outcomes[0].attrs["message"] == "expected 1"


def test_a_doctype_cut_by_a_chunk_boundary_reaches_the_parser_whole(tmp_path: Path) -> None:
    """The first chunk ends 200 characters into an entity's value: no markup to hold back."""
    why = "expected 1, " + "." * 400
    comment = "<!--" + "c" * (reader.CHUNK_BYTES - len(DECLARATION) - 250) + "-->"
    text = _with_doctype(
        f'<!ENTITY why "{why}">',
        '<failure message="&why;">&why;</failure>',
        DECLARATION + comment,
    )
    assert text.index("<!DOCTYPE") < reader.CHUNK_BYTES - 200
    assert "<" not in text[reader.CHUNK_BYTES - 200 : reader.CHUNK_BYTES + 100]
    read = read_text(tmp_path, text)
    assert (read.problems, read.repairs) == ([], [reader.DOCTYPE_REMOVED])
    assert read.cases[1].outcomes[0].text == why


def test_lines_around_the_doctype_keep_their_numbers(tmp_path: Path) -> None:
    """The parser sees the DOCTYPE at its own line; what else the prolog held, as breaks."""
    prolog = f"{DECLARATION}<!-- one\ntwo -->\n<?pi three?>\n"
    text = _with_doctype("\n<!ENTITY why 'w'>\n", "\n\n<failure message='&why;'>", prolog)
    assert text.count("\n", 0, text.index("<failure")) == 9
    read = read_text(tmp_path, text)
    [problem] = read.problems
    assert "cut off or broken at line 10 " in problem
