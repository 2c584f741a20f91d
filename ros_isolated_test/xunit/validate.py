"""A result's canonical xUnit bytes, checked against our schema; result_file writes them.

A result built only from the runner's own words (passed, skipped, not run, no result
file) has one fixed shape that the test suite validates against ``schemas/junit.xsd``;
it is rendered without loading lxml. A result holding what a test's own file said is
validated here, at run time, with its counts re-checked: one that fails is a bug of
ours, and becomes a valid document that says so instead of being lost.
"""

from __future__ import annotations

import os
import time

from ros_isolated_test import names
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.model import Case, Outcome, Suite
from ros_isolated_test.xunit.xml_text import name_token

TYPE_CHECKING = False
if TYPE_CHECKING:
    from lxml import etree


def timestamp(when: float | None = None) -> str:
    """Local time to the second, the form every reader (and our schema) accepts."""
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(when))


def hostname() -> str:
    """The machine's name; never empty (the schema requires one)."""
    return os.uname().nodename.strip() or "localhost"


def problems(root: etree._Element) -> list[str]:
    """Why a tree is not canonical: schema errors, then counts that disagree with cases.

    The counts include the ``flaky_cases`` property a merge of attempts writes.
    """
    from ros_isolated_test.schemas import junit_schema

    schema = junit_schema()
    if not schema.validate(root):
        return [f"line {error.line}: {error.message}" for error in list(schema.error_log)]  # type: ignore[call-overload]
    found: list[str] = []
    for suite in root.iter("testsuite"):
        cases = suite.findall("testcase")
        expected = {
            "tests": len(cases),
            "failures": sum(1 for case in cases if case.find("failure") is not None),
            "errors": sum(1 for case in cases if case.find("error") is not None),
            "skipped": sum(1 for case in cases if case.find("skipped") is not None),
        }
        for key, value in expected.items():
            if suite.get(key) != str(value):
                found.append(
                    f"suite {suite.get('name')}: {key}={suite.get(key)}, cases say {value}"
                )
        flaky = sum(  # passed after failing: a skip after failing is a skip
            1
            for case in cases
            if (case.find("flakyFailure") is not None or case.find("flakyError") is not None)
            and case.find("skipped") is None
        )
        for prop in suite.iterfind(f"properties/property[@name='{names.FLAKY_CASES}']"):
            if prop.get("value") != str(flaky):
                found.append(
                    f"suite {suite.get('name')}: property {names.FLAKY_CASES}={prop.get('value')},"
                    f" cases say {flaky}"
                )
    return found


class Rendered:
    """A canonical file's bytes, and whether it reports a failure or an error."""

    __slots__ = ("data", "failed")

    def __init__(self, data: bytes, failed: bool) -> None:
        self.data = data
        self.failed = failed


def render(suite: Suite, validate: bool = True) -> Rendered:
    """The canonical file; an invalid document becomes a valid one saying why (a failure).

    ``validate=False`` is for the runner's own fixed-shape results only. ``failed`` is
    that of the suite written, so a result replaced by the internal error case fails
    the run instead of passing it silently.
    """
    written = suite
    data = serialise.serialize(written)
    if validate:
        found = _problems_of(data)
        if found:
            written = _internal_error(suite, found)
            data = serialise.serialize(written)
            if _problems_of(data):
                written = _internal_error(_bare(suite), found)
                data = serialise.serialize(written)
    return Rendered(data, written.failed)


def _problems_of(data: bytes) -> list[str]:
    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=True)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as error:
        return [f"not well-formed: {error}"]
    return problems(root)


def _bare(suite: Suite) -> Suite:
    """The suite stripped of everything it got from outside, for the last-resort file."""
    return Suite(
        name="ros_isolated_test.result",
        cases=suite.cases,
        time=0.0,
        timestamp=timestamp(),
        hostname="localhost",
    )


def _internal_error(suite: Suite, found: list[str]) -> Suite:
    failed = sum(1 for case in suite.cases if case.outcome.failed)
    message = (
        "ros-isolated-test built a result that does not match its own schema (a bug: please "
        f"report it). The test had {len(suite.cases)} case(s), {failed} failed or errored. "
        f"Schema problems: {'; '.join(found[:5])}"
    )
    case = Case.saying(
        name_token(suite.name, "ros_isolated_test.result"),
        "result file",
        Outcome.ERROR,
        message,
        "InternalError",
    )
    return Suite(
        name=suite.name,
        cases=[case],
        time=suite.time,
        timestamp=timestamp(),
        hostname=hostname(),
        properties={
            key: value
            for key, value in suite.properties.items()
            if key and value and key != names.FLAKY_CASES
        },
    )
