"""``schemas``: ``junit.xsd``, a strict subset of Jenkins' junit-10, parsed once per process.

A file valid here is read the same way by colcon test-result, xunit-viewer, Jenkins,
GitLab and the GitHub reporters: exactly the shapes below, each outcome with the
attempts it may carry. Every shape ours accepts, junit-10 accepts too (checked by the
junit-10 rules in code, and in the outside tier by the real junit-10.xsd); some that
junit-10 accepts ours refuses, and what junit-10 refuses ours refuses as well.
"""

from __future__ import annotations

import pytest
from helpers import capabilities, jenkins_junit10
from helpers.xunit import failed, parse, passed, real_junit10, suite_of
from lxml import etree

from ros_isolated_test.schemas import junit_schema
from ros_isolated_test.xunit import serialise, validate
from ros_isolated_test.xunit.attempts import merge_attempts
from ros_isolated_test.xunit.model import Case, Outcome


def test_junit_schema_accepts_a_canonical_file_and_rejects_a_bad_one() -> None:
    merged = merge_attempts([suite_of([failed(), failed("b")]), suite_of([passed(), failed("b")])])
    merged.cases.append(Case("pkg.C", "s", outcome=Outcome.SKIPPED, message="no GPU"))
    root = parse(serialise.serialize(merged))
    schema = junit_schema()
    assert schema.validate(root), schema.error_log
    case = root.find("testsuite/testcase")
    assert case is not None
    etree.SubElement(case, "properties")  # properties only at suite level
    assert not schema.validate(root)


def test_the_schema_is_parsed_once_per_process() -> None:
    assert junit_schema() is junit_schema()


# --- the shapes: exactly these, a subset of junit-10 ------------------------------------------


_CASE = '<testcase classname="pkg.C" name="a" time="0.000">{}</testcase>'


_DOC = (
    '<testsuites name="s" tests="1" failures="{f}" errors="0" time="0.000">'
    '<testsuite name="s" tests="1" failures="{f}" errors="0" skipped="{s}" time="0.000"'
    ' timestamp="2026-01-01T00:00:00" hostname="h"><properties>'
    '<property name="runner_version" value="0"/></properties>{case}</testsuite></testsuites>'
)


_FLAKY = '<flakyFailure message="m" type="T"><stackTrace>t</stackTrace></flakyFailure>'


_RERUN = '<rerunError message="m" type="T"><system-out>o</system-out></rerunError>'


_FAILURE = '<failure message="m">t</failure>'


#: Documents our schema accepts: each an outcome with the attempts it may carry.
ACCEPTED = {
    "passed": ("", 0, 0),
    "flaky pass": (_FLAKY, 0, 0),
    "flaky error and failure": (_FLAKY + _FLAKY.replace("flakyFailure", "flakyError"), 0, 0),
    "skipped then flaky": ('<skipped message=""/>' + _FLAKY, 0, 1),
    "failure with reruns": (_FAILURE + _RERUN + _RERUN.replace("rerunError", "rerunFailure"), 1, 0),
    "all three children": (
        _FAILURE + '<rerunFailure message="m" type="T"><stackTrace>t</stackTrace>'
        "<system-out>o</system-out><system-err>e</system-err></rerunFailure>"
        "<system-out>o</system-out>",
        1,
        0,
    ),
}


#: Documents our schema rejects although junit-10 accepts every one of them.
REJECTED = {
    "flaky beside a failure": (_FAILURE + _FLAKY, 1, 0),
    "rerun after a pass": (_RERUN, 0, 0),
    "rerun after a skip": ('<skipped message=""/>' + _RERUN, 0, 1),
    "attempt before the outcome": (_RERUN + _FAILURE, 1, 0),
    "flaky before the skip": (_FLAKY + '<skipped message=""/>', 0, 1),
    "attempt after the output": (_FAILURE + "<system-out>o</system-out>" + _RERUN, 1, 0),
    "mixed text in an attempt": ('<flakyFailure message="m" type="T">text</flakyFailure>', 0, 0),
    "blank type": ('<flakyFailure message="m" type=" "/>', 0, 0),
    "no message": ('<flakyFailure type="T"/>', 0, 0),
    "empty stack trace": ('<flakyFailure message="m" type="T"><stackTrace/></flakyFailure>', 0, 0),
}


#: What junit-10 itself rejects, which ours must reject too.
REJECTED_BY_BOTH = {
    "no type": ('<flakyFailure message="m"/>', 0, 0),
    "unknown child": ('<rerunFailure message="m" type="T"><x/></rerunFailure>', 1, 0),
    "children out of order": (
        '<flakyFailure message="m" type="T"><system-out>o</system-out>'
        "<stackTrace>t</stackTrace></flakyFailure>",
        0,
        0,
    ),
}


def _document(body: str, failures: int, skipped: int) -> etree._Element:
    return etree.fromstring(_DOC.format(f=failures, s=skipped, case=_CASE.format(body)))


@pytest.mark.parametrize("name", sorted(ACCEPTED))
def test_our_schema_accepts_each_outcome_with_its_attempts(name: str) -> None:
    root = _document(*ACCEPTED[name])
    assert junit_schema().validate(root), junit_schema().error_log
    assert validate.problems(root) == []
    assert jenkins_junit10.rejections(root) == []


@pytest.mark.parametrize("name", sorted(REJECTED))
def test_our_schema_rejects_shapes_junit10_allows(name: str) -> None:
    root = _document(*REJECTED[name])
    assert not junit_schema().validate(root)
    assert jenkins_junit10.rejections(root) == []


@pytest.mark.parametrize("name", sorted(REJECTED_BY_BOTH))
def test_what_junit10_rejects_ours_rejects(name: str) -> None:
    root = _document(*REJECTED_BY_BOTH[name])
    assert not junit_schema().validate(root)
    assert jenkins_junit10.rejections(root) != []


# --- the outside tier: the real junit-10.xsd ----------------------------------------------------


@pytest.fixture(scope="module")
def junit10_xsd() -> etree.XMLSchema:
    """The schema Jenkins' xunit-plugin validates "JUnit" input with."""
    return real_junit10()


@capabilities.OUTSIDE
@pytest.mark.parametrize("name", sorted(ACCEPTED))
def test_real_junit10_accepts_every_shape_ours_accepts(
    junit10_xsd: etree.XMLSchema, name: str
) -> None:
    assert junit10_xsd.validate(_document(*ACCEPTED[name])), junit10_xsd.error_log


@capabilities.OUTSIDE
@pytest.mark.parametrize("name", sorted(REJECTED))
def test_real_junit10_accepts_the_shapes_only_ours_rejects(
    junit10_xsd: etree.XMLSchema, name: str
) -> None:
    """Ours is a strict subset: these show it is strictly smaller, not different."""
    assert junit10_xsd.validate(_document(*REJECTED[name])), junit10_xsd.error_log


@capabilities.OUTSIDE
@pytest.mark.parametrize("name", sorted(REJECTED_BY_BOTH))
def test_real_junit10_rejects_what_both_reject(junit10_xsd: etree.XMLSchema, name: str) -> None:
    assert not junit10_xsd.validate(_document(*REJECTED_BY_BOTH[name]))
