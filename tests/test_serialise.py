"""The runner's own result files, written without lxml: valid, lossless, readable by lxml.

Results the runner writes itself (passed, skipped, not run, no result file) are not
validated at run time, so this file is where their shape is proven: every document the
serializer makes from hostile values must validate against ``schemas/junit.xsd`` and
give the values back as they were made safe.
"""

from __future__ import annotations

import random

import pytest
from lxml import etree

from ros_isolated_test import __version__
from ros_isolated_test.xunit import serialise, validate
from ros_isolated_test.xunit.attempts import for_outcome
from ros_isolated_test.xunit.model import ATTEMPT_KINDS, Attempt, Case, Outcome, Suite
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT, name_token, xml_safe

_HOSTILE = [
    "",
    " ",
    "plain",
    "quote \" apostrophe ' amp & lt < gt >",
    "]]> and <![CDATA[ x ]]>",
    "tab\tnewline\ncr\rcrlf\r\n",
    "\x00\x01\x08\x0b\x0c\x1f controls",
    "\x1b[31mred\x1b[0m",
    "lone \udcff surrogate and \ud800",
    "replacement \ufffd and \ufffe \uffff",
    "wide \U0001f916 robot, é, 日本",
    "&amp; &#1; &#x41; already escaped",
    "<testcase name='x'/></testsuite>",
]


def _parse(data: bytes) -> etree._Element:
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=True)
    return etree.fromstring(data, parser)


def _suite(cases: list[Case], **kwargs: object) -> Suite:
    values: dict[str, object] = {
        "name": "pkg.test",
        "cases": cases,
        "time": 1.5,
        "timestamp": validate.timestamp(),
        "hostname": "host",
    }
    values.update(kwargs)
    return Suite(**values)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", _HOSTILE)
@pytest.mark.parametrize("outcome", list(Outcome))
def test_every_hostile_value_gives_a_valid_file_that_reads_back(
    value: str, outcome: Outcome
) -> None:
    case = Case(
        "pkg.C" + value,
        "t" + value,
        time=0.25,
        outcome=outcome,
        message=value,
        text=value + " text",
        type=value,
        system_out=value + " out",
        system_err=value + " err",
    )
    suite = _suite(
        [case],
        properties={"command": value, "k" + value: value},
        system_out=value + " suite out",
        system_err=value + " suite err",
    )
    data = serialise.serialize(suite)
    root = _parse(data)
    assert validate.problems(root) == []
    element = root.find("testsuite/testcase")
    assert element is not None
    assert element.get("classname") == name_token("pkg.C" + value, "unnamed")
    assert element.get("name") == name_token("t" + value, "unnamed")
    assert element.findtext("system-out") == xml_safe(value + " out")
    command = root.find("testsuite/properties/property[@name='command']")
    assert command is not None and command.get("value") == xml_safe(value)
    if outcome is Outcome.PASSED:
        assert len(element.findall("*")) == 2  # system-out, system-err
        return
    node = element.find(outcome.value)
    assert node is not None
    assert node.get("message") == xml_safe(value)
    assert node.text == xml_safe(value + " text")
    # A type is a name: written as one trimmed line, absent when that is empty.
    assert node.get("type", "") == name_token(value, "")


def test_line_ends_and_tabs_survive_in_attributes_and_text() -> None:
    value = "a\tb\nc\rd\r\ne"
    case = Case.saying("pkg.C", "t", Outcome.FAILURE, value)
    root = _parse(serialise.serialize(_suite([case])))
    failure = root.find("testsuite/testcase/failure")
    assert failure is not None
    assert failure.get("message") == value
    assert failure.text == value


def test_counts_come_from_the_cases() -> None:
    cases = [
        Case("pkg.C", "a"),
        Case.saying("pkg.C", "b", Outcome.FAILURE, "f"),
        Case.saying("pkg.C", "c", Outcome.ERROR, "e"),
        Case.saying("pkg.C", "d", Outcome.ERROR, "e"),
        Case.saying("pkg.C", "e", Outcome.SKIPPED, "s"),
    ]
    root = _parse(serialise.serialize(_suite(cases)))
    suite = root.find("testsuite")
    assert suite is not None
    assert [suite.get(key) for key in ("tests", "failures", "errors", "skipped")] == [
        "5",
        "1",
        "2",
        "1",
    ]
    assert [root.get(key) for key in ("tests", "failures", "errors")] == ["5", "1", "2"]
    assert validate.problems(root) == []


def test_the_runner_version_is_always_a_property() -> None:
    root = _parse(serialise.serialize(_suite([Case("pkg.C", "a")])))
    assert (
        root.find("testsuite/properties/property[@name='runner_version']").get(  # type: ignore[union-attr]
            "value"
        )
        == __version__
    )


def test_a_skipped_case_without_message_is_an_empty_element() -> None:
    case = Case("pkg.C", "a", outcome=Outcome.SKIPPED)
    data = serialise.serialize(_suite([case]))
    assert b'<skipped message=""/>' in data
    assert validate.problems(_parse(data)) == []


def test_long_output_is_cut_to_the_text_limit_keeping_both_ends() -> None:
    output = "BEGIN" + "x" * (3 * TEXT_LIMIT) + "END"
    root = _parse(serialise.serialize(_suite([Case("pkg.C", "a")], system_out=output)))
    kept = root.findtext("testsuite/system-out") or ""
    assert kept.startswith("BEGIN") and kept.endswith("END")
    assert len(kept) < TEXT_LIMIT + 200


def test_the_layout_is_lxmls_pretty_print() -> None:
    """Same bytes as lxml's serializer: readers that diff files see no change of writer."""
    cases = [
        Case("pkg.C", "a", time=0.5),
        Case.saying("pkg.C", "b", Outcome.FAILURE, 'x < "y"\n', "AssertionError"),
        Case("pkg.C", "c", outcome=Outcome.SKIPPED, system_out="out\r\n"),
    ]
    suite = _suite(cases, properties={"command": "echo 'a b'"}, system_out="tail")
    data = serialise.serialize(suite)
    again = etree.tostring(_parse(data), xml_declaration=True, encoding="UTF-8", pretty_print=True)
    assert data == again


def test_random_values_always_validate() -> None:
    rng = random.Random(7)
    alphabet = [chr(code) for code in range(0, 0x80)] + ["\ud800", "\ufffd", "é", "\U0001f916"]
    bad: list[str] = []
    for _ in range(200):

        def word() -> str:
            return "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 30)))

        cases = [
            Case(
                word(),
                word(),
                time=rng.random() * 10,
                outcome=rng.choice(list(Outcome)),
                message=word(),
                text=word(),
                type=word(),
                system_out=word(),
            )
            for _ in range(rng.randint(1, 4))
        ]
        # Two cases of one name would break the schema's unique key: the runner's own
        # results never have more than one case, and adopted ones are validated anyway.
        for index, case in enumerate(cases):
            case.name = f"{index} {case.name}"
            attempts = [
                Attempt(rng.choice(ATTEMPT_KINDS), word(), word(), word(), word(), word())
                for _ in range(rng.randint(0, 3))
            ]
            case.attempts = for_outcome(attempts, case.outcome)
        suite = _suite(cases, name=word(), hostname=word(), properties={word(): word()})
        data = serialise.serialize(suite)
        found = validate.problems(_parse(data))
        if found:
            bad.append(f"{data[:300]!r}: {found[:2]}")
    assert bad == []
