"""Shapes that one reader reads differently from the others, made canonical so all agree.

Each rule below is written here from the readers' documented behaviour (issue 14 and
../shared/reference/xunit-formats.md), independently of the code under test:

- GitLab keys a case by ``"<suite>_<classname>_<name>"`` and keeps one case per key.
- GitLab turns the XML into a hash with ActiveSupport's converter, which refuses
  ``type="yaml"`` and ``type="symbol"`` (exact match) and fails on ``type="date"`` /
  ``"datetime"`` whose text is no date; either drops the whole file.
- Jenkins drops a suite without a ``<testcase>``.
- ament and colcon trust a suite's count attributes, the others its elements.
- Surefire's rerun and flaky elements are earlier attempts, not output.

Each file is normalised in-process (``normalise_file``, what the runner does with a
test's own file) and checked as canonical; the zero-case rule also runs real pytest
under the RUNNER. A DOCTYPE's entities are ``test_reader_entities``'.
"""

from __future__ import annotations

import datetime
import re
import sys
from pathlib import Path

import pytest
from helpers.canonical import check_canonical
from helpers.commands import run_runner
from helpers.xunit import SAMPLES, canonical_of, repairs, suite_xml
from lxml import etree

from ros_isolated_test.xunit import normalise, reader
from ros_isolated_test.xunit.model import Outcome

# --- GitLab: one case per "<suite>_<classname>_<name>" ------------------------------------


def gitlab_cases(root: etree._Element) -> dict[str, str]:
    """GitLab's reading: key -> outcome, the first case of a key kept, later ones lost."""
    kept: dict[str, str] = {}
    for suite_node in root.iter("testsuite"):
        for node in suite_node.iter("testcase"):
            key = f"{suite_node.get('name')}_{node.get('classname')}_{node.get('name')}"
            outcome = next(
                (tag for tag in ("failure", "error", "skipped") if node.find(tag) is not None),
                "success",
            )
            kept.setdefault(key, outcome)
    return kept


def test_gitlab_keys_of_different_cases_never_collide(tmp_path: Path) -> None:
    data = suite_xml(
        '<testcase classname="a" name="b_c"><failure message="m">t</failure></testcase>'
        '<testcase classname="a_b" name="c"/>'
        # Already named the way a renamed case would be: the rename must avoid it.
        '<testcase classname="a_b" name="c [2]"/>'
    )
    result, _ = canonical_of(tmp_path, data)
    names = [(case.classname, case.name, case.outcome) for case in result.summary.cases]
    assert names == [
        ("pkg.a", "b_c", "failure"),
        ("pkg.a_b", "c [3]", "passed"),
        ("pkg.a_b", "c [2]", "passed"),
    ]
    # GitLab now shows the three cases and the failure, as every other reader does.
    assert sorted(gitlab_cases(result.root).values()) == ["failure", "success", "success"]
    assert "1 test case(s) renamed whose GitLab key" in repairs(result)
    assert "pkg.a_b 'c' as 'c [3]'" in repairs(result)


def test_control_gitlab_rule_collapses_the_raw_file(tmp_path: Path) -> None:
    """The rule itself loses the passing case of the raw file: it can fail the test above."""
    raw = etree.fromstring(
        suite_xml(
            '<testcase classname="pkg.a" name="b_c"><failure message="m">t</failure></testcase>'
            '<testcase classname="pkg.a_b" name="c"/>',
            head="",
        )
    )
    assert list(gitlab_cases(raw).values()) == ["failure"]


def test_cases_whose_keys_differ_keep_their_names(tmp_path: Path) -> None:
    data = suite_xml('<testcase classname="a" name="b"/><testcase classname="a" name="b_c"/>')
    result, _ = canonical_of(tmp_path, data)
    assert [case.name for case in result.summary.cases] == ["b", "b_c"]
    assert "renamed" not in repairs(result)


# --- GitLab: its XML type converter -------------------------------------------------------


def gitlab_converter_refuses(root: etree._Element) -> list[str]:
    """Why ActiveSupport's Hash.from_xml would fail on ``root`` (GitLab drops the file)."""
    found = []
    for node in root.iter():
        kind = node.get("type")
        if kind in ("yaml", "symbol"):
            found.append(f"<{node.tag} type={kind!r}>: disallowed type attribute")
        elif kind in ("date", "datetime", "dateTime") and (node.text or "").strip():
            try:
                datetime.datetime.fromisoformat(node.text.strip())  # type: ignore[union-attr]
            except ValueError:
                found.append(f"<{node.tag} type={kind!r}>: {node.text!r} is no date")
    return found


@pytest.mark.parametrize("tag", ["failure", "error", "skipped"])
@pytest.mark.parametrize("kind", ["yaml", "symbol", "date", "datetime"])
def test_types_gitlab_converts_are_written_safely_and_kept(
    tmp_path: Path, tag: str, kind: str
) -> None:
    data = suite_xml(
        f'<testcase classname="C" name="t"><{tag} message="went wrong" type="{kind}">'
        f"AssertionError: 1 != 2</{tag}></testcase>"
    )
    raw = etree.fromstring(data.encode())
    assert gitlab_converter_refuses(raw), "control: GitLab refuses the producer's file"
    result, _ = canonical_of(tmp_path, data)
    assert gitlab_converter_refuses(result.root) == []
    node = result.element("t").find(tag)
    assert node is not None
    assert node.get("type") == f"{kind} (producer type)"  # what the producer said, kept
    assert node.get("message") == "went wrong"
    assert node.text == "AssertionError: 1 != 2"
    assert f"GitLab's XML converter would act on ({kind})" in repairs(result)


@pytest.mark.parametrize("kind", ["AssertionError", "pytest.skip", "YAML", "", "string"])
def test_other_types_pass_through(tmp_path: Path, kind: str) -> None:
    """ActiveSupport matches types exactly: ``YAML`` and ``string`` are harmless."""
    data = suite_xml(
        f'<testcase classname="C" name="t"><failure message="m" type="{kind}">t</failure>'
        "</testcase>"
    )
    result, _ = canonical_of(tmp_path, data)
    node = result.element("t").find("failure")
    assert node is not None
    assert node.get("type", "") == kind
    assert "GitLab" not in repairs(result)


@pytest.mark.parametrize("tag", ["failure", "flakyFailure", "rerunError"])
@pytest.mark.parametrize("kind", [" yaml", "symbol ", "  date\t"])
def test_types_gitlab_converts_are_caught_as_written_not_as_given(
    tmp_path: Path, tag: str, kind: str
) -> None:
    """Names are written trimmed: the converter's check must see the trimmed value."""
    data = suite_xml(
        f'<testcase classname="C" name="t"><{tag} message="went wrong" type="{kind}">'
        f"not a date</{tag}></testcase>"
    )
    result, _ = canonical_of(tmp_path, data)
    assert gitlab_converter_refuses(result.root) == []
    [node] = [child for child in result.element("t") if child.get("message") == "went wrong"]
    assert node.get("type") == f"{kind.strip()} (producer type)"
    assert f"GitLab's XML converter would act on ({kind.strip()})" in repairs(result)


# --- counts a producer claims but shows in no case ----------------------------------------


CLAIMS = {
    "tests": (' tests="3"', "1 more test case(s)"),
    "failures": (' failures="1"', "1 more failure(s) or error(s)"),
    "errors": (' errors="1"', "1 more failure(s) or error(s)"),
    "skipped": (' skipped="1"', "1 more skipped test(s)"),
    "disabled": (' disabled="1"', "1 more skipped test(s)"),
}


@pytest.mark.parametrize("claim", sorted(CLAIMS))
def test_every_claimed_count_no_case_shows_becomes_one_error_case(
    tmp_path: Path, claim: str
) -> None:
    attrs, said = CLAIMS[claim]
    data = suite_xml('<testcase classname="C" name="a"/><testcase classname="C" name="b"/>', attrs)
    result, _ = canonical_of(tmp_path, data)
    assert result.counts == (3, 0, 1, 0)
    case = result.case("unreported test cases")
    assert case.outcome == "error"
    assert said in case.message
    assert "the producer reported them nowhere else" in case.message


def test_claims_several_counts_miss_are_said_in_one_case(tmp_path: Path) -> None:
    data = suite_xml('<testcase classname="C" name="a"/>', ' tests="4" failures="1" skipped="2"')
    result, _ = canonical_of(tmp_path, data)
    assert result.counts == (2, 0, 1, 0)
    assert result.case("unreported test cases").message.startswith(
        "The result file's own counts claim 3 more test case(s) and 1 more failure(s) or "
        "error(s) and 2 more skipped test(s) than its test cases show"
    )


@pytest.mark.parametrize(
    "attrs",
    [
        ' tests="3" failures="1" errors="0" skipped="1"',
        # More elements than claimed: pytest's duplicates and reruns, not a loss.
        ' tests="1" failures="0" skipped="0"',
    ],
)
def test_control_counts_the_cases_show_add_no_case(tmp_path: Path, attrs: str) -> None:
    data = suite_xml(
        '<testcase classname="C" name="a"/>'
        '<testcase classname="C" name="b"><failure message="m">t</failure></testcase>'
        '<testcase classname="C" name="c"><skipped message="s"/></testcase>',
        attrs,
    )
    result, _ = canonical_of(tmp_path, data)
    assert result.counts == (3, 1, 0, 1)


def test_damaged_file_says_what_its_counts_miss_in_its_one_error_case(tmp_path: Path) -> None:
    data = suite_xml(
        '<testcase classname="C" name="a"/><testcase classname="C" name="b"><failure message="m',
        ' tests="3" failures="1"',
    )
    data = data[: data.index('message="m') + 10]
    result, _ = canonical_of(tmp_path, data)
    outcomes = [(case.name, case.outcome) for case in result.summary.cases]
    assert outcomes == [("a", "passed"), ("b", "error"), ("result file", "error")]
    assert result.case("result file").message.endswith(
        "Its own counts claim 1 more test case(s) and 1 more failure(s) or error(s) than "
        "the kept test cases show."
    )


# --- a suite with no test cases -----------------------------------------------------------


def jenkins_suites(root: etree._Element) -> list[str]:
    """Jenkins keeps a suite only if it has a direct ``<testcase>``."""
    return [
        node.get("name", "") for node in root.iter("testsuite") if node.find("testcase") is not None
    ]


def test_no_test_cases_is_one_skipped_case_every_reader_shows(tmp_path: Path) -> None:
    sample = SAMPLES / "pytest-9.2_no_tests.xml"
    assert jenkins_suites(etree.parse(str(sample)).getroot()) == [], "control: Jenkins drops it"
    result, _ = canonical_of(tmp_path, sample.read_bytes(), "pytest-9.2_no_tests")
    assert jenkins_suites(result.root) == ["pkg.pytest-9.2_no_tests"]
    assert result.counts == (1, 0, 0, 1)
    case = result.case("no test cases")
    assert case.classname == "pkg.pytest-9.2_no_tests"
    assert case.message.startswith("The result file reports no test cases")
    assert case.text == case.message


def test_control_a_suite_with_cases_gets_no_such_case(tmp_path: Path) -> None:
    result, _ = canonical_of(
        tmp_path, suite_xml('<testcase classname="C" name="s"><skipped/></testcase>')
    )
    assert [case.name for case in result.summary.cases] == ["s"]


def test_pytest_collecting_nothing_fails_the_run_and_says_why(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """Real pytest, no tests, exit code 5: a failed run showing that nothing was tested."""
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "test_nothing.py").write_text("VALUE = 1\n")
    result = tmp_path / "build" / "pkg" / "t.xml"
    command = [
        sys.executable,
        "-m",
        "pytest",
        "-p",
        "no:cacheprovider",
        f"--junit-xml={result}",
        str(tmp_path / "tests"),
    ]
    proc = run_runner(
        runner_script,
        [str(result), "--package-name", "pkg", "--command", *command],
        env,
        cwd=tmp_path,
    )
    assert proc.returncode == 5, proc.stdout + proc.stderr
    canonical = check_canonical(result, "pkg", "t")
    assert canonical.properties["exit_code"] == "5"
    assert canonical.case("no test cases").outcome == "skipped"
    assert canonical.case("test process exit").outcome == "failure"
    assert canonical.counts == (2, 1, 0, 1)


# --- a producer's own Surefire rerun and flaky elements -----------------------------------


SUREFIRE = suite_xml(
    '<testcase classname="C" name="flaky">'
    '<flakyFailure message="first try" type="AssertionError"><stackTrace>trace 1'
    "</stackTrace><system-out>out 1</system-out><system-err>err 1</system-err>"
    "</flakyFailure>"
    '<flakyError message="second try" type="IOError">trace 2</flakyError>'
    "</testcase>"
    '<testcase classname="C" name="always"><failure message="third" type="T">t3</failure>'
    '<rerunFailure message="first" type="yaml">t1<system-out>o1</system-out></rerunFailure>'
    '<rerunError message="second" type="E">t2</rerunError></testcase>'
    # A producer that names attempts after the wrong final outcome: read as Surefire means.
    '<testcase classname="C" name="wrong"><rerunFailure message="w" type="T"/></testcase>'
)


def test_surefire_attempts_become_attempts_not_output(tmp_path: Path) -> None:
    source = tmp_path / "t.xml"
    source.write_text(SUREFIRE)
    cases = {case.name: case for case in normalise.cases_from(reader.read(source), "pkg", "t")}
    flaky = cases["flaky"]
    assert flaky.outcome is Outcome.PASSED
    assert flaky.system_out == ""
    assert [
        (a.kind, a.message, a.type, a.text, a.system_out, a.system_err) for a in flaky.attempts
    ] == [
        ("flakyFailure", "first try", "AssertionError", "trace 1", "out 1", "err 1"),
        ("flakyError", "second try", "IOError", "trace 2", "", ""),
    ]
    assert flaky.flaky
    always = cases["always"]
    assert always.outcome is Outcome.FAILURE
    assert always.message == "third"
    assert [(a.kind, a.message, a.type, a.text, a.system_out) for a in always.attempts] == [
        ("rerunFailure", "first", "yaml (producer type)", "t1", "o1"),
        ("rerunError", "second", "E", "t2", ""),
    ]
    assert [a.kind for a in cases["wrong"].attempts] == ["flakyFailure"]


def test_surefire_attempts_are_kept_as_elements(tmp_path: Path) -> None:
    result, _ = canonical_of(tmp_path, SUREFIRE)
    assert result.counts == (3, 1, 0, 0)
    flaky = result.element("flaky")
    # A flaky pass's output comes first (xunit-viewer takes the status from it).
    assert [child.tag for child in flaky] == ["system-out", "flakyFailure", "flakyError"]
    first = flaky[1]
    assert first.get("message") == "first try"
    assert "trace 1" in etree.tostring(first, method="text", encoding="unicode")
    assert first.findtext("system-out") == "out 1"
    always = result.element("always")
    assert [child.tag for child in always] == ["failure", "rerunFailure", "rerunError"]
    assert gitlab_converter_refuses(result.root) == []
    assert re.search(r"\btype attribute\(s\) GitLab", repairs(result))
