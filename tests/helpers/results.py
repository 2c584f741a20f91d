"""Reading the result files tests get back, strictly, and writing ones a test writes itself.

Every result file a test reads passes through ``load_result``: the runner does not
validate its own files at run time, so this is where they are checked against our schema
and their counts.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from ros_isolated_test.xunit import validate

#: What the runner says when the test left no result file of its own.
NO_RESULT = "did not generate a result file"
#: The runner's first line: the ID, and the Gazebo partition beside it when one is set.
DOMAIN_LINE = re.compile(
    r"Running with ROS_DOMAIN_ID (\d+)(?: \(Gazebo partition [A-Za-z0-9_.-]+\))?"
)


@dataclass(frozen=True)
class CaseResult:
    """One ``<testcase>``: its outcome and the text of its failure/error/skipped child."""

    classname: str
    name: str
    outcome: str
    message: str
    text: str


@dataclass(frozen=True)
class ResultSummary:
    """What a result file says, after checking it is well-formed xUnit."""

    suites: tuple[str, ...]
    cases: tuple[CaseResult, ...]
    properties: dict[str, str]

    @property
    def only(self) -> CaseResult:
        assert len(self.cases) == 1, self.cases
        return self.cases[0]


_OUTCOMES = ("failure", "error", "skipped")


def load_result(path: Path) -> ResultSummary:
    """Parse ``path`` with lxml and check it: our schema, root ``testsuites``, counts that match.

    Fails the calling test if the file is not the xUnit every CI tool reads. Every file
    the runner writes passes through here: the runner's own results are not validated
    at run time, so this is where they are.
    """
    assert path.is_file(), f"no result file at {path}"
    root = etree.parse(str(path), etree.XMLParser(resolve_entities=False)).getroot()
    assert validate.problems(root) == [], f"{path} does not match schemas/junit.xsd"
    assert root.tag == "testsuites", f"root is <{root.tag}>, not <testsuites>"
    suites: list[str] = []
    cases: list[CaseResult] = []
    properties: dict[str, str] = {}
    totals = dict.fromkeys(("tests", "failures", "errors", "skipped"), 0)
    for suite in root.iter("testsuite"):
        suites.append(suite.get("name", ""))
        suite_cases = [_case(node) for node in suite.findall("testcase")]
        counts = {
            "tests": len(suite_cases),
            "failures": sum(case.outcome == "failure" for case in suite_cases),
            "errors": sum(case.outcome == "error" for case in suite_cases),
            "skipped": sum(case.outcome == "skipped" for case in suite_cases),
        }
        for attribute, expected in counts.items():
            value = suite.get(attribute)
            assert value is not None, f"suite {suites[-1]!r} lacks {attribute}="
            assert re.fullmatch(r"\d+", value), f"{attribute}={value!r} is not an integer"
            assert int(value) == expected, f"{attribute}={value} but {expected} such cases"
            totals[attribute] += expected
        for prop in suite.iter("property"):
            properties[prop.get("name", "")] = prop.get("value", "")
        cases.extend(suite_cases)
    for attribute, expected in totals.items():
        value = root.get(attribute)
        if value is not None:
            assert int(value) == expected, f"<testsuites {attribute}={value}> but {expected}"
    assert suites, "no <testsuite> in the result file"
    return ResultSummary(tuple(suites), tuple(cases), properties)


def _case(node: etree._Element) -> CaseResult:
    children = [child for child in node if child.tag in _OUTCOMES]
    assert len(children) <= 1, f"test case with several outcomes: {[c.tag for c in children]}"
    outcome = str(children[0].tag) if children else "passed"
    message = children[0].get("message", "") if children else ""
    text = (children[0].text or "") if children else ""
    return CaseResult(node.get("classname", ""), node.get("name", ""), outcome, message, text)


def own_result(path: Path, cases: Sequence[tuple[str, str, str]], classname: str = "C") -> bytes:
    """A result file as a test writes it itself: ``(name, outcome, text)`` per case."""
    root = etree.Element("testsuites")
    suite = etree.SubElement(
        root,
        "testsuite",
        name="own",
        tests=str(len(cases)),
        failures=str(sum(outcome == "failure" for _, outcome, _ in cases)),
        errors=str(sum(outcome == "error" for _, outcome, _ in cases)),
        skipped=str(sum(outcome == "skipped" for _, outcome, _ in cases)),
    )
    for name, outcome, text in cases:
        case = etree.SubElement(suite, "testcase", classname=classname, name=name)
        if outcome != "passed":
            etree.SubElement(case, outcome, message=text).text = text
    data = bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    path.write_bytes(data)
    return data


def domain_of(stdout: str) -> int:
    match = DOMAIN_LINE.search(stdout)
    assert match, f"no 'Running with ROS_DOMAIN_ID' line in:\n{stdout}"
    return int(match.group(1))


def result_error(result_file: Path) -> str:
    """The message of the one ``<error>`` a refusal result file holds."""
    errors = etree.parse(str(result_file)).getroot().findall("./testsuite/testcase/error")
    assert len(errors) == 1, [etree.tostring(error) for error in errors]
    return errors[0].get("message") or ""
