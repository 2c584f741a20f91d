"""``xunit.serialise``: the runner's own result files, written without lxml: valid, lossless.

Results the runner writes itself (passed, skipped, not run, no result file) are not
validated at run time, so this file is where their shape is proven: every document the
serializer makes from hostile values must validate against ``schemas/junit.xsd`` and
give the values back as they were made safe. Earlier attempts are written as Surefire
writes them (junit-10 wants a ``type``, the text in ``stackTrace``), and a flaky pass
opens with output saying so, because xunit-viewer takes a case's status from its first
child. The bytes are lxml's ``pretty_print`` layout, and writing them loads no lxml.
"""

from __future__ import annotations

import random

import pytest
from helpers.xunit import (
    CLASS,
    attempts_of,
    canonical_root,
    case_node,
    child_tags,
    failed,
    modules_loaded,
    parse,
    passed,
    suite_of,
)
from lxml import etree

from ros_isolated_test import __version__
from ros_isolated_test.xunit import serialise, validate
from ros_isolated_test.xunit.attempts import for_outcome, merge_attempts
from ros_isolated_test.xunit.model import ATTEMPT_KINDS, Attempt, Case, Outcome
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
    suite = suite_of(
        [case],
        properties={"command": value, "k" + value: value},
        system_out=value + " suite out",
        system_err=value + " suite err",
    )
    data = serialise.serialize(suite)
    root = parse(data)
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
    root = parse(serialise.serialize(suite_of([case])))
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
    root = parse(serialise.serialize(suite_of(cases)))
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
    root = parse(serialise.serialize(suite_of([Case("pkg.C", "a")])))
    assert (
        root.find("testsuite/properties/property[@name='runner_version']").get(  # type: ignore[union-attr]
            "value"
        )
        == __version__
    )


def test_a_skipped_case_without_message_is_an_empty_element() -> None:
    case = Case("pkg.C", "a", outcome=Outcome.SKIPPED)
    data = serialise.serialize(suite_of([case]))
    assert b'<skipped message=""/>' in data
    assert validate.problems(parse(data)) == []


def test_long_output_is_cut_to_the_text_limit_keeping_both_ends() -> None:
    output = "BEGIN" + "x" * (3 * TEXT_LIMIT) + "END"
    root = parse(serialise.serialize(suite_of([Case("pkg.C", "a")], system_out=output)))
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
    suite = suite_of(cases, properties={"command": "echo 'a b'"}, system_out="tail")
    data = serialise.serialize(suite)
    again = etree.tostring(parse(data), xml_declaration=True, encoding="UTF-8", pretty_print=True)
    assert data == again


def test_the_layout_with_attempts_is_lxmls_pretty_print() -> None:
    merged = merge_attempts(
        [suite_of([failed(), failed("b")]), suite_of([passed(), failed("b", "again")])]
    )
    data = serialise.serialize(merged)
    again = etree.tostring(parse(data), xml_declaration=True, encoding="UTF-8", pretty_print=True)
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
        suite = suite_of(cases, name=word(), hostname=word(), properties={word(): word()})
        data = serialise.serialize(suite)
        found = validate.problems(parse(data))
        if found:
            bad.append(f"{data[:300]!r}: {found[:2]}")
    assert bad == []


def test_writing_a_result_loads_no_lxml() -> None:
    """The module's reason to be: every test's runner writes a file, lxml would cost more."""
    write = (
        "from ros_isolated_test.xunit import serialise\n"
        "from ros_isolated_test.xunit.model import Case, Suite\n"
        "serialise.serialize(Suite('pkg.t', [Case('pkg.C', 'a')], 0.0, 'x', 'h'))"
    )
    assert modules_loaded(write, "lxml") == [False]
    # The control: the probe sees lxml when something does load it.
    assert modules_loaded(f"{write}\nimport lxml.etree", "lxml") == [True]


# --- earlier attempts, as Surefire writes them ----------------------------------------------


def test_a_flaky_pass_opens_with_its_output_saying_so_once_however_often_re_read() -> None:
    """xunit-viewer takes a case's status from its first child: an attempt there reads "?"."""
    case = passed()
    case.system_out = "the test's own output"
    case.attempts = [Attempt("flakyFailure", "first try")]
    node = case_node(canonical_root(suite_of([case])), "a")
    assert child_tags(node) == ["system-out", "flakyFailure"]
    note = "Passed after 1 failed attempt(s); each is recorded below."
    assert node.findtext("system-out") == f"{note}\nthe test's own output"
    # Written again from what a reader gets back: the line is not added twice.
    case.system_out = str(node.findtext("system-out"))
    again = case_node(canonical_root(suite_of([case])), "a")
    assert again.findtext("system-out") == f"{note}\nthe test's own output"


@pytest.mark.parametrize(
    ("kind", "expected"),
    [("flakyFailure", "failure"), ("flakyError", "error"), ("rerunError", "error")],
)
@pytest.mark.parametrize("given", ["", "  ", "\x00\n"])
def test_an_attempt_without_type_gets_its_outcome_as_type(
    kind: str, expected: str, given: str
) -> None:
    outcome = Outcome.ERROR if kind.startswith("rerun") else Outcome.PASSED
    case = Case(CLASS, "a", outcome=outcome, message="m")
    case.attempts = [Attempt(kind, "m", given)]
    node = case_node(canonical_root(suite_of([case])), "a")
    [attempt] = node.iter(kind)
    assert attempt.get("type") == (expected if given != "\x00\n" else "\\x00")


def test_an_attempt_without_text_has_its_message_as_stack_trace_and_without_both_is_empty() -> None:
    case = passed()
    case.attempts = [Attempt("flakyFailure", "only a message"), Attempt("flakyFailure")]
    first, second = attempts_of(case_node(canonical_root(suite_of([case])), "a"))
    assert first.findtext("stackTrace") == "only a message"
    assert (len(second), second.get("message")) == (0, "")


def test_hostile_attempt_values_stay_valid_and_read_back() -> None:
    value = 'quote " amp & lt < ]]> \x1b[31mred\x1b[0m \x01 tab\tcr\r \ud800 robot \U0001f916'
    case = passed()
    case.attempts = [Attempt("flakyFailure", value, value, value, value, value)]
    (attempt,) = attempts_of(case_node(canonical_root(suite_of([case])), "a"))
    shown = 'quote " amp & lt < ]]> red \\x01 tab\tcr\r \\ud800 robot \U0001f916'
    assert attempt.get("message") == shown
    assert attempt.findtext("stackTrace") == shown
    assert attempt.findtext("system-err") == shown
