"""Would the Jenkins xunit-plugin accept a file as "JUnit"? Its junit-10.xsd, as rules.

Written from the team's notes on the schema (which elements and attributes it allows,
its time pattern), not from the schema text, so a test can say *why* a file is rejected.
The outside tier of test_jenkins_checker.py validates the same documents with the real
junit-10.xsd and fails on any verdict that differs, but one: the schema declares every
element global, so a lone ``<testcase>`` (or ``<failure>``) validates as a document; the
checker takes only ``testsuites`` or ``testsuite`` as the root of a result file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

#: junit-10's SUREFIRE_TIME: digits and commas, with at least three digits after the last
#: comma ("1,234", "1234,567"; not "0,5" or "1,"), then at most three decimals.
SUREFIRE_TIME = re.compile(r"(?:[0-9,]*,[0-9]{3,}|[0-9]*)(?:\.[0-9]{0,3})?")
#: Attributes every XSD validator allows on any element.
_XSI = "{http://www.w3.org/2001/XMLSchema-instance}"
_OUTCOME_ATTRS = frozenset({"type", "message"})
_RERUN_CHILDREN = ("stackTrace", "system-out", "system-err")


@dataclass(frozen=True)
class Rule:
    """What junit-10 allows for one element."""

    attributes: frozenset[str] = frozenset()
    required: frozenset[str] = frozenset()
    children: frozenset[str] = frozenset()
    #: Whether character data may appear (mixed or simple content).
    text: bool = False
    #: Children that must come in this order, each at most once (rerun/flaky elements).
    ordered: tuple[str, ...] = ()


_RERUN = Rule(
    attributes=_OUTCOME_ATTRS,
    required=frozenset({"type"}),
    children=frozenset(_RERUN_CHILDREN),
    text=True,
    ordered=_RERUN_CHILDREN,
)
_TEXT_ONLY = Rule(text=True)

RULES: dict[str, Rule] = {
    "testsuites": Rule(
        attributes=frozenset({"name", "time", "tests", "failures", "errors"}),
        children=frozenset({"testsuite"}),
    ),
    "testsuite": Rule(
        attributes=frozenset(
            {
                "name",
                "tests",
                "failures",
                "errors",
                "group",
                "time",
                "skipped",
                "timestamp",
                "hostname",
                "id",
                "package",
                "file",
                "log",
                "url",
            }
        ),
        required=frozenset({"name", "tests", "failures", "errors"}),
        children=frozenset({"testsuite", "properties", "testcase", "system-out", "system-err"}),
    ),
    "properties": Rule(children=frozenset({"property"})),
    "property": Rule(
        attributes=frozenset({"name", "value"}), required=frozenset({"name", "value"})
    ),
    "testcase": Rule(
        attributes=frozenset({"name", "time", "classname", "group"}),
        required=frozenset({"name"}),
        children=frozenset(
            {
                "skipped",
                "error",
                "failure",
                "rerunFailure",
                "rerunError",
                "flakyFailure",
                "flakyError",
                "system-out",
                "system-err",
            }
        ),
    ),
    "failure": Rule(attributes=_OUTCOME_ATTRS, text=True),
    "error": Rule(attributes=_OUTCOME_ATTRS, text=True),
    "skipped": Rule(attributes=_OUTCOME_ATTRS, text=True),
    "rerunFailure": _RERUN,
    "rerunError": _RERUN,
    "flakyFailure": _RERUN,
    "flakyError": _RERUN,
    "stackTrace": _TEXT_ONLY,
    "system-out": _TEXT_ONLY,
    "system-err": _TEXT_ONLY,
}
_TIMED = frozenset({"testsuites", "testsuite"})


def rejections(tree: etree._Element | etree._ElementTree) -> list[str]:
    """Why junit-10 would reject the document; empty when it would accept it."""
    root = tree.getroot() if isinstance(tree, etree._ElementTree) else tree
    if not isinstance(root.tag, str) or root.tag not in ("testsuites", "testsuite"):
        return [f"root <{root.tag}> is neither <testsuites> nor <testsuite>"]
    found: list[str] = []
    _check(root, found)
    return found


def accepts(tree: etree._Element | etree._ElementTree) -> bool:
    """Whether junit-10 would accept the document."""
    return not rejections(tree)


def file_rejections(path: Path) -> list[str]:
    """Why junit-10 would reject the file: not well-formed (or empty), or :func:`rejections`."""
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    try:
        root = etree.fromstring(path.read_bytes(), parser)
    except etree.XMLSyntaxError as error:
        return [f"not well-formed XML: {error}"]
    return rejections(root)


def _check(element: etree._Element, found: list[str]) -> None:
    name = str(element.tag)
    rule = RULES.get(name)
    if rule is None:
        found.append(f"<{name}> is not a junit-10 element")
        return
    for attribute, value in element.attrib.items():
        key = str(attribute)
        if key.startswith(_XSI):
            continue
        if key not in rule.attributes:
            found.append(f"<{name}> has undeclared attribute {key!r}")
        elif key == "time" and name in _TIMED and not SUREFIRE_TIME.fullmatch(str(value)):
            found.append(f"<{name}> time={value!r} does not match SUREFIRE_TIME")
    found.extend(
        f"<{name}> lacks required attribute {key!r}"
        for key in sorted(rule.required)
        if key not in element.attrib
    )
    if not rule.text and _has_text(element):
        found.append(f"<{name}> holds character data, but its content is elements only")
    children = [child for child in element if isinstance(child.tag, str)]
    for child in children:
        if child.tag not in rule.children:
            found.append(f"<{name}> may not contain <{child.tag}>")
        else:
            _check(child, found)
    if rule.ordered:
        tags = [str(child.tag) for child in children]
        positions = [rule.ordered.index(tag) for tag in tags if tag in rule.ordered]
        if positions != sorted(set(positions)):
            found.append(f"<{name}> children {tags} are not {list(rule.ordered)}, each once")


def _has_text(element: etree._Element) -> bool:
    """Non-blank character data directly in ``element`` (comments and PIs do not count)."""
    if element.text and element.text.strip():
        return True
    return any(child.tail and child.tail.strip() for child in element)
