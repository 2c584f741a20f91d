"""The parser every result file goes through: it loads nothing external, and its errors.

libxml2's settings that make a parser safe on its own, whatever it is fed, and the words
for where and why it stopped. Apart so that the one place to audit what the parser may
load is small, and shared by the reading and by the sanitiser's check of a DOCTYPE.
"""

from __future__ import annotations

import re
from typing import cast

from lxml import etree

#: How libxml2 says it stopped expanding an entity: too far (2.11 and later), in a loop,
#: too deeply nested (2.11 and later; before, a loop too).
_ENTITY_BOMB = re.compile(
    r"entity amplification|entity reference loop|entity nesting depth", re.IGNORECASE
)


class _NothingExternal(etree.Resolver):
    """Answers every DTD, entity or file the parser would load with nothing.

    ``resolve_entities='internal'`` refuses external general entities only: libxml2
    before 2.13 still loads an external parameter entity (``%p;``) from a file here
    (lxml 5.2.1's bundled 2.12 does, and so does Ubuntu 24.04's 2.9.14).
    """

    def resolve(  # type: ignore[override]  # lxml passes a context; its stubs omit it
        self, system_url: str, public_id: str, context: object
    ) -> object:
        return self.resolve_string("", context, base_url=None)


def new_parser(target: object | None = None) -> etree.XMLParser:
    """The parser every result file is read with: safe on its own, whatever it is fed.

    libxml2 expands a DOCTYPE's internal entities and nothing else: no DTD, external
    entity or URL is loaded, and without ``huge_tree`` it keeps its limits on entity
    expansion (2.11 and later) and on one text, name or attribute value. It does not
    bound one huge attribute, CDATA section or comment in memory: ``markup`` does.
    """
    parser = etree.XMLParser(
        target=cast("etree.ParserTarget | None", target),
        resolve_entities="internal",  # type: ignore[arg-type]  # lxml-stubs predate lxml 5
        load_dtd=False,
        no_network=True,
        huge_tree=False,
        remove_pis=True,
    )
    parser.resolvers.add(_NothingExternal())
    return parser


def message(error: etree.XMLSyntaxError) -> str:
    """What libxml2 said; its own words end with the line and column it stopped at."""
    return str(error.msg if hasattr(error, "msg") else error).strip()


def describe(error: etree.XMLSyntaxError, *, root_seen: bool, inside: bool) -> str:
    """Why and where reading stopped, given whether a root element began and one is open."""
    said = message(error)
    if _ENTITY_BOMB.search(said):
        # Where libxml2 says it stopped is inside the entity, not a line of the file.
        return (
            "entity references expand too far, too deep or in a loop (an entity bomb?): "
            f"reading stopped there (libxml2: {said})"
        )
    where = f"line {error.lineno}" if getattr(error, "lineno", None) else "somewhere"
    if not root_seen:
        return f"not XML ({said} at {where})"
    if inside:
        return f"the file is cut off or broken at {where} ({said}); what came before is kept"
    return f"not well-formed at {where}: {said}"
