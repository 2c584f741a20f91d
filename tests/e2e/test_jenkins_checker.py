"""The junit-10 checker rejects what Jenkins' xunit-plugin rejects, and only that.

Without this the "valid here is valid there" tests elsewhere could pass with a checker
that accepts anything. The samples (tests/data/xunit) and the expected reasons run
everywhere; the outside tier also validates every sample and every document below with
the real junit-10.xsd (../shared/reference/xunit-schemas, CI only) and requires the same
verdict from the checker.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities, jenkins_junit10
from helpers.xunit import SAMPLES
from lxml import etree

from ros_isolated_test.xunit import serialise, validate
from ros_isolated_test.xunit.attempts import merge_attempts
from ros_isolated_test.xunit.model import Case, Outcome, Suite

#: Samples junit-10 accepts as they are (section 5.1's table; pytest xunit2 without
#: record_property, so without testcase <properties>).
ACCEPTED = (
    "ament_run_test_missing_result.xml",
    "ament_run_test_missing_result_tidied_ansi.xml",
    "ament_run_test_skip_result.xml",
    "ament_run_test_success_result.xml",
    "launch_testing_junitxml.xml",
    "pytest-9.2_collection_error.xml",
    "pytest-9.2_fail_plus_teardown_error.xml",
    "pytest-9.2_no_tests.xml",
    "pytest-9.2_rerunfailures.xml",
    "pytest-9.2_xunit2_junit_logging_all.xml",
)

_GTEST_CASE = (
    "<testcase> has undeclared attribute 'file'",
    "<testcase> has undeclared attribute 'line'",
    "<testcase> has undeclared attribute 'status'",
    "<testcase> has undeclared attribute 'result'",
    "<testcase> has undeclared attribute 'timestamp'",
    "<testsuite> has undeclared attribute 'disabled'",
    "<testsuites> has undeclared attribute 'disabled'",
    "<testsuites> has undeclared attribute 'timestamp'",
)
_GTEST_MIXED = (
    *_GTEST_CASE,
    "<testcase> has undeclared attribute 'value_param'",
    "<testcase> has undeclared attribute 'type_param'",
    "<testcase> may not contain <properties>",
)
_CTEST = (
    "<testsuite> lacks required attribute 'errors'",
    "<testsuite> has undeclared attribute 'disabled'",
    "<testcase> has undeclared attribute 'status'",
)
_XMLRUNNER = (
    "<testcase> has undeclared attribute 'file'",
    "<testcase> has undeclared attribute 'line'",
    "<testcase> has undeclared attribute 'timestamp'",
)

#: Samples junit-10 rejects, with every reason section 5.1 gives for them.
REJECTED: dict[str, tuple[str, ...]] = {
    "ctest-3.25.1_output-junit.xml": _CTEST,
    "ctest-4.4.4_output-junit.xml": (*_CTEST, "<testcase> may not contain <properties>"),
    "gtest-1.12.1_env_failure.xml": (
        *_GTEST_CASE,
        # <= 1.15 writes environment properties as attributes of the root.
        "<testsuites> has undeclared attribute 'envkey'",
        "<testsuites> has undeclared attribute 'random_seed'",
        "<testcase> may not contain <properties>",
    ),
    "gtest-1.12.1_mixed.gtest.xml": (
        *_GTEST_MIXED,
        # <= 1.15 writes SetUpTestSuite properties as attributes of the suite.
        "<testsuite> has undeclared attribute 'suitekey'",
    ),
    "gtest-1.17.0_env_failure.xml": (
        *_GTEST_CASE,
        # >= 1.16 writes them as <properties> of the root instead.
        "<testsuites> may not contain <properties>",
        "<testcase> may not contain <properties>",
    ),
    "gtest-1.17.0_mixed.gtest.xml": _GTEST_MIXED,
    "gtest-1.17.0_setupsuite_failure_after_run_test.gtest.xml": _GTEST_CASE,
    "pytest-9.2_xunit1.xml": (
        "<testcase> has undeclared attribute 'file'",
        "<testcase> has undeclared attribute 'line'",
        "<testcase> has undeclared attribute 'custom_attr'",
        "<testcase> may not contain <properties>",
    ),
    # record_property was used: xunit2 keeps the testcase <properties>.
    "pytest-9.2_xunit2.xml": ("<testcase> may not contain <properties>",),
    "xmlrunner-4.0_per_class_file.xml": _XMLRUNNER,
    # The setUpClass error case has a timestamp but no file or line.
    "xmlrunner-4.0_setUpClass_error.xml": ("<testcase> has undeclared attribute 'timestamp'",),
    "xmlrunner-4.0_single_file.xml": _XMLRUNNER,
}

#: Not well-formed at all: gtest passes invalid UTF-8 through, launch_testing writes a
#: raw control character. Their structure is still judged, read with recovery.
NOT_WELL_FORMED = (
    "gtest-1.12.1_mixed.gtest.xml",
    "gtest-1.17.0_mixed.gtest.xml",
    "launch_testing_junitxml_ctrlchar_INVALID.xml",
)


def _recovered(path: Path) -> etree._Element:
    return etree.fromstring(path.read_bytes(), etree.XMLParser(recover=True))


def test_every_sample_has_a_verdict() -> None:
    judged = set(ACCEPTED) | set(REJECTED) | set(NOT_WELL_FORMED)
    assert judged == {path.name for path in SAMPLES.glob("*.xml")}


@pytest.mark.parametrize("name", ACCEPTED)
def test_accepts_what_junit10_accepts(name: str) -> None:
    assert jenkins_junit10.file_rejections(SAMPLES / name) == []


@pytest.mark.parametrize("name", sorted(REJECTED))
def test_rejects_samples_for_the_reasons_junit10_has(name: str) -> None:
    path = SAMPLES / name
    found = set(jenkins_junit10.rejections(_recovered(path)))
    missing = [reason for reason in REJECTED[name] if reason not in found]
    assert not missing, f"{name}: expected {missing} among {sorted(found)}"
    assert jenkins_junit10.file_rejections(path)


@pytest.mark.parametrize("name", NOT_WELL_FORMED)
def test_rejects_files_that_are_not_well_formed(name: str) -> None:
    found = jenkins_junit10.file_rejections(SAMPLES / name)
    assert len(found) == 1
    assert found[0].startswith("not well-formed XML")


def test_launch_testing_structure_is_fine_apart_from_the_character() -> None:
    path = SAMPLES / "launch_testing_junitxml_ctrlchar_INVALID.xml"
    assert jenkins_junit10.rejections(_recovered(path)) == []


def test_rejects_an_empty_file(tmp_path: Path) -> None:
    empty = tmp_path / "empty.xml"
    empty.write_bytes(b"")
    assert jenkins_junit10.file_rejections(empty)[0].startswith("not well-formed XML")


# --- synthetic documents: one rule each ------------------------------------------------------

SUITE = '<testsuite name="s" tests="1" failures="0" errors="0"{attrs}>{body}</testsuite>'
ONE_CASE = '<testcase name="c"/>'


def _suite_text(body: str = ONE_CASE, attrs: str = "") -> str:
    return SUITE.format(attrs=attrs, body=body)


def _doc(text: str) -> list[str]:
    return jenkins_junit10.rejections(etree.fromstring(text))


def _suite(body: str = ONE_CASE, attrs: str = "") -> list[str]:
    return _doc(_suite_text(body, attrs))


PLAIN_VALID = (
    '<testsuites name="all" time="1.5" tests="2" failures="1" errors="0">'
    '<testsuite name="s" tests="2" failures="1" errors="0" skipped="0" time="1.5" '
    'timestamp="2026-01-01T00:00:00" hostname="h" id="0" package="p" file="f" log="l" '
    'url="u" group="g">'
    '<properties><property name="k" value=""/></properties>'
    '<testcase name="a" classname="C" time="0.5" group="g"/>'
    '<testcase name="b" classname="C" time="whatever">'
    '<failure message="m" type="T">text</failure><system-out>o</system-out>'
    "<system-err>e</system-err></testcase>"
    "<system-out>suite out</system-out><system-err>suite err</system-err>"
    "</testsuite></testsuites>"
)
FREE_COUNTS = '<testsuite name="s" tests="x" failures="" errors="1.0"/>'
ACCEPTED_TIMES = ("0", "0.", "1,234.5", "", "12.125", "1,234,567", "1234,567", ".5")
REJECTED_TIMES = ("1e-05", "-1", " 1", "0,5", "NaN", "1.5s", "inf", "12.1234", "1,", "0.0001")
REQUIRED = ("name", "tests", "failures", "errors")
REJECTED_CONTENT = (
    ('<testcase name="c" file="f.py"/>', "<testcase> has undeclared attribute 'file'"),
    ('<testcase name="c"><failure kind="x"/></testcase>', "<failure> has undeclared"),
    ('<testcase name="c"><properties/></testcase>', "<testcase> may not contain <prop"),
    ('<testcase name="c"><foo/></testcase>', "<testcase> may not contain <foo>"),
    ('<testcase name="c"><failure><b>x</b></failure></testcase>', "<failure> may not"),
    ('<testcase name="c">stray text</testcase>', "<testcase> holds character data"),
    ("<properties><property name='k'/></properties>", "lacks required attribute 'value'"),
    ("<properties><property value='v'/></properties>", "lacks required attribute 'name'"),
    ("<properties><foo/></properties>", "<properties> may not contain <foo>"),
    ("<system-out><b>x</b></system-out>", "<system-out> may not contain <b>"),
    ("stray text", "<testsuite> holds character data"),
    ('<testcase name="c"><rerunFailure/></testcase>', "lacks required attribute 'type'"),
    (
        '<testcase name="c"><rerunFailure type="T"><system-out>o</system-out>'
        "<stackTrace>s</stackTrace></rerunFailure></testcase>",
        "<rerunFailure> children",
    ),
    ("<testcase/>", "<testcase> lacks required attribute 'name'"),
)
RERUN_WITH_TYPE = (
    '<testcase name="c"><rerunFailure type="T" message="m">text<stackTrace>s</stackTrace>'
    '<system-out>o</system-out></rerunFailure><flakyError type="T"/></testcase>'
)
COMMENTED = '\n  <!-- a docstring -->\n  <testcase name="c"><!-- c --></testcase>\n'
OTHER_ROOTS = ("<testcase name='c'/>", "<report/>", '<x:testsuite xmlns:x="urn:x" name="s"/>')
NAMESPACED_CHILD = '<testcase name="c"><x:failure xmlns:x="urn:x"/></testcase>'
TESTSUITES_CONTENT = (
    '<testsuites><testcase name="c"/></testsuites>',
    "<testsuites><properties/></testsuites>",
    '<testsuites skipped="0"/>',
)


def _without(attribute: str) -> str:
    attrs = {"name": "s", "tests": "0", "failures": "0", "errors": "0"}
    del attrs[attribute]
    return "<testsuite " + " ".join(f'{k}="{v}"' for k, v in attrs.items()) + "/>"


def test_a_plain_valid_document_is_accepted() -> None:
    assert _doc(PLAIN_VALID) == []


def test_counts_are_free_strings() -> None:
    assert _doc(FREE_COUNTS) == []


@pytest.mark.parametrize("time", ACCEPTED_TIMES)
def test_surefire_time_accepted(time: str) -> None:
    assert _suite(attrs=f' time="{time}"') == []
    assert _doc(f'<testsuites time="{time}"/>') == []


@pytest.mark.parametrize("time", REJECTED_TIMES)
def test_surefire_time_rejected(time: str) -> None:
    assert _suite(attrs=f' time="{time}"') == [
        f"<testsuite> time={time!r} does not match SUREFIRE_TIME"
    ]
    assert _doc(f'<testsuites time="{time}"/>') != []


def test_testcase_time_is_a_free_string() -> None:
    assert _suite('<testcase name="c" time="1e-05"/>') == []


@pytest.mark.parametrize("attribute", REQUIRED)
def test_testsuite_required_attributes(attribute: str) -> None:
    assert _doc(_without(attribute)) == [f"<testsuite> lacks required attribute {attribute!r}"]


def test_testcase_needs_a_name_and_nothing_else() -> None:
    assert _suite("<testcase/>") == ["<testcase> lacks required attribute 'name'"]
    assert _suite(ONE_CASE) == []


@pytest.mark.parametrize(("body", "reason"), REJECTED_CONTENT)
def test_rejected_content(body: str, reason: str) -> None:
    found = _suite(body)
    assert any(reason in item for item in found), found


def test_rerun_and_flaky_elements_with_type_are_accepted() -> None:
    assert _suite(RERUN_WITH_TYPE) == []


def _attempt_suite(*outcomes: Outcome) -> Suite:
    """One attempt's canonical suite: case ``c<i>`` has the i-th outcome, with every text."""
    cases = [
        Case(
            "pkg.C",
            f"c{index}",
            outcome=outcome,
            message=f"{outcome.value} message",
            text=f"{outcome.value} text",
            type="" if index % 2 else "AssertionError",
            system_out="out",
            system_err="err",
        )
        for index, outcome in enumerate(outcomes)
    ]
    return Suite("pkg.t", cases, 1.0, validate.timestamp(), "h", system_out="console")


def _canonical_text(*attempts: Suite) -> str:
    data = serialise.serialize(merge_attempts(attempts)).decode()
    return data.split("\n", 1)[1]  # lxml parses no str with an encoding declaration


F, E, P, S = Outcome.FAILURE, Outcome.ERROR, Outcome.PASSED, Outcome.SKIPPED
#: Canonical files of rerun tests (issue 14): flaky*, rerun* and cases that came and went.
CANONICAL_ATTEMPTS = (
    _canonical_text(_attempt_suite(F, E, F, S), _attempt_suite(P, P, S, P)),
    _canonical_text(_attempt_suite(F, E), _attempt_suite(E, F), _attempt_suite(F, E)),
    _canonical_text(_attempt_suite(F), _attempt_suite(E, P), _attempt_suite(P, P, F)),
    _canonical_text(_attempt_suite(F, F, F), _attempt_suite()),
)


@pytest.mark.parametrize("text", CANONICAL_ATTEMPTS)
def test_canonical_files_with_every_attempt_shape_are_accepted(text: str) -> None:
    root = etree.fromstring(text)
    tags = {str(node.tag) for node in root.iter()}
    assert jenkins_junit10.rejections(root) == []
    assert validate.problems(root) == []
    assert tags & {"flakyFailure", "flakyError", "rerunFailure", "rerunError"}


def test_every_attempt_element_appears_in_the_canonical_documents() -> None:
    """Else the outside tier below would not put one of them before the real schema."""
    tags = {str(node.tag) for text in CANONICAL_ATTEMPTS for node in etree.fromstring(text).iter()}
    assert tags >= {"flakyFailure", "flakyError", "rerunFailure", "rerunError", "stackTrace"}


def test_nested_suites_are_allowed() -> None:
    assert _suite(_suite_text()) == []


def test_testsuites_holds_only_testsuite_elements() -> None:
    assert [_doc(text) for text in TESTSUITES_CONTENT] == [
        ["<testsuites> may not contain <testcase>"],
        ["<testsuites> may not contain <properties>"],
        ["<testsuites> has undeclared attribute 'skipped'"],
    ]


def test_comments_and_whitespace_are_not_content() -> None:
    assert _suite(COMMENTED) == []


@pytest.mark.parametrize("text", OTHER_ROOTS)
def test_other_roots_are_rejected(text: str) -> None:
    assert _doc(text)[0].startswith("root <")


def test_namespaced_elements_are_unknown() -> None:
    found = _suite(NAMESPACED_CHILD)
    assert found == ["<testcase> may not contain <{urn:x}failure>"]


# --- the outside tier: the same verdicts from the real junit-10.xsd --------------------------

#: Every synthetic document above, each judged by the checker in one of the tests above.
SYNTHETIC: tuple[str, ...] = (
    PLAIN_VALID,
    FREE_COUNTS,
    *(_suite_text(attrs=f' time="{time}"') for time in ACCEPTED_TIMES + REJECTED_TIMES),
    *(f'<testsuites time="{time}"/>' for time in ACCEPTED_TIMES + REJECTED_TIMES),
    _suite_text('<testcase name="c" time="1e-05"/>'),
    *(_without(attribute) for attribute in REQUIRED),
    _suite_text(),
    *(_suite_text(body) for body, _ in REJECTED_CONTENT),
    _suite_text(RERUN_WITH_TYPE),
    _suite_text(_suite_text()),
    *TESTSUITES_CONTENT,
    _suite_text(COMMENTED),
    *OTHER_ROOTS,
    _suite_text(NAMESPACED_CHILD),
    *CANONICAL_ATTEMPTS,
)

#: Documents the schema accepts and the checker rejects on purpose: not a suite root.
SUITE_ROOTS_ONLY = frozenset({"<testcase name='c'/>"})


@pytest.fixture(scope="module")
def junit10_xsd() -> Iterator[etree.XMLSchema]:
    """The real schema Jenkins' xunit-plugin validates "JUnit" input with."""
    capabilities.require(capabilities.OUTSIDE)
    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    yield etree.XMLSchema(etree.parse(str(capabilities.JENKINS_JUNIT10_XSD), parser))


def _verdicts(schema: etree.XMLSchema, root: etree._Element) -> tuple[bool, bool]:
    """(the real schema accepts, the checker accepts) for one document."""
    return schema.validate(root), jenkins_junit10.accepts(root)


@capabilities.OUTSIDE
@pytest.mark.parametrize("name", sorted(set(ACCEPTED) | set(REJECTED) | set(NOT_WELL_FORMED)))
def test_real_junit10_gives_each_sample_the_same_verdict(
    junit10_xsd: etree.XMLSchema, name: str
) -> None:
    """Files that are not well-formed are compared on what recovery reads of them."""
    schema, checker = _verdicts(junit10_xsd, _recovered(SAMPLES / name))
    assert schema == checker, f"{name}: junit-10.xsd {schema}, checker {checker}"
    assert schema == (name in ACCEPTED or name == "launch_testing_junitxml_ctrlchar_INVALID.xml")


@capabilities.OUTSIDE
@pytest.mark.parametrize("text", SYNTHETIC)
def test_real_junit10_gives_each_synthetic_document_the_same_verdict(
    junit10_xsd: etree.XMLSchema, text: str
) -> None:
    """Except one deliberate difference: the schema declares every element global, so a
    lone ``<testcase>`` validates; the checker accepts only suite roots as a result file."""
    schema, checker = _verdicts(junit10_xsd, etree.fromstring(text))
    if text in SUITE_ROOTS_ONLY:
        assert (schema, checker) == (True, False), text
    else:
        assert schema == checker, f"junit-10.xsd {schema}, checker {checker}: {text}"


@capabilities.OUTSIDE
@pytest.mark.parametrize("text", CANONICAL_ATTEMPTS)
def test_real_junit10_accepts_canonical_files_with_every_attempt_shape(
    junit10_xsd: etree.XMLSchema, text: str
) -> None:
    assert junit10_xsd.validate(etree.fromstring(text)), junit10_xsd.error_log


@capabilities.OUTSIDE
def test_control_the_real_schema_rejects_and_accepts(junit10_xsd: etree.XMLSchema) -> None:
    """The comparisons above can fail: the schema really judges (it is not accept-all)."""
    assert junit10_xsd.validate(etree.fromstring(PLAIN_VALID))
    assert not junit10_xsd.validate(etree.fromstring(_without("errors")))
