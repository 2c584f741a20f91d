"""``xunit.safe_parser``: the parser loads nothing external, whatever it is fed.

The reader passes a result file's DOCTYPE to this parser, which expands internal
entities and loads nothing else. So the parser is tested here on its own, bypassing
every sanitiser step: an external entity or DTD is never read, a URL never fetched,
and an entity bomb is refused in bounded memory; each with a control showing that the
same document does name a readable file, a reachable server, a real expansion. Its
words for where and why reading stopped are the ones the reader reports.
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
from helpers.xunit import BOMBS, MB, billion_laughs, quadratic_blowup
from lxml import etree

from ros_isolated_test.xunit import safe_parser

#: Peak RSS allowed for a child that parses a bomb; an interpreter with lxml takes about
#: 20 MB.
MAX_RSS = 100 * MB
TOKEN = "SECRET-TOKEN-0x5eed"


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
    parser = safe_parser.new_parser(target)
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
from ros_isolated_test.xunit import safe_parser
try:
    root = etree.fromstring(Path(sys.argv[1]).read_bytes(), safe_parser.new_parser())
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
    assert etree.fromstring(document.encode(), safe_parser.new_parser()).text == expanded


# --- where and why it stopped -----------------------------------------------------------


def _stopped(document: bytes) -> etree.XMLSyntaxError:
    with pytest.raises(etree.XMLSyntaxError) as caught:
        etree.fromstring(document, safe_parser.new_parser())
    return caught.value


def test_the_reason_reading_stopped_says_where_and_why() -> None:
    cut = _stopped(b"<testsuite>\n<testcase>")
    assert safe_parser.describe(cut, root_seen=True, inside=True).startswith(
        "the file is cut off or broken at line 2 ("
    )
    assert safe_parser.describe(cut, root_seen=False, inside=False).startswith("not XML (")
    extra = _stopped(b"<a/>\n<b/>")
    said = safe_parser.describe(extra, root_seen=True, inside=False)
    assert said.startswith("not well-formed at line 2: ")
    assert said.endswith(safe_parser.message(extra))


def test_an_entity_bomb_is_named_as_one_not_by_a_line() -> None:
    bomb = _stopped(billion_laughs(10).encode())
    said = safe_parser.describe(bomb, root_seen=True, inside=True)
    assert said.startswith("entity references expand too far, too deep or in a loop")
    assert "reading stopped there" in said
    loop = _stopped(b'<!DOCTYPE r [<!ENTITY a "&b;"><!ENTITY b "&a;">]><r>&a;</r>')
    assert "an entity bomb?" in safe_parser.describe(loop, root_seen=True, inside=True)
    # The control: an entity used a few times is no bomb.
    assert etree.fromstring(quadratic_blowup(3, 10).encode(), safe_parser.new_parser()).text == (
        "B" * 30
    )
