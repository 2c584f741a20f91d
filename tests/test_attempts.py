"""Every attempt of a rerun test on record: merged, bounded, serialised, valid everywhere.

Each merged suite is written by the real serialiser and checked by our schema with its
counts, by the junit-10 rules (and, in the outside tier, by the real junit-10.xsd), and
read back as xUnit: a flaky pass is a pass with ``flakyFailure`` beside it, a case that
failed every time is its ``failure`` with one ``rerunFailure`` per earlier attempt.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities, jenkins_junit10
from lxml import etree

from ros_isolated_test.schemas import junit_schema
from ros_isolated_test.xunit import normalise, reader, serialise, validate
from ros_isolated_test.xunit.attempts import (
    ABSENT,
    ATTEMPT_TEXT_LIMIT,
    ATTEMPTS_KEPT,
    NOT_RUN_AGAIN,
    NOT_RUN_AGAIN_TYPE,
    RENAMED_PROPERTY,
    for_outcome,
    kept,
    merge_attempts,
)
from ros_isolated_test.xunit.model import Attempt, Case, Outcome, Suite
from ros_isolated_test.xunit.result_file import normalise_file
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT

CLASS = "pkg.C"
ATTEMPT_TAGS = ("flakyFailure", "flakyError", "rerunFailure", "rerunError")


def _suite(cases: list[Case], **kwargs: object) -> Suite:
    values: dict[str, object] = {
        "name": "pkg.test",
        "cases": cases,
        "time": 1.0,
        "timestamp": validate.timestamp(),
        "hostname": "host",
    }
    values.update(kwargs)
    return Suite(**values)  # type: ignore[arg-type]


def _passed(name: str = "a") -> Case:
    return Case(CLASS, name, time=0.25)


def _failed(name: str = "a", message: str = "boom", outcome: Outcome = Outcome.FAILURE) -> Case:
    return Case(
        CLASS,
        name,
        outcome=outcome,
        message=message,
        text=f"Traceback: {message}",
        type="AssertionError" if outcome is Outcome.FAILURE else "RuntimeError",
        system_out=f"out of {message}",
    )


def _huge(text: str) -> Case:
    """A failure whose every text is ``text``."""
    return Case(
        CLASS,
        "a",
        outcome=Outcome.FAILURE,
        message=text,
        text=text,
        type="T",
        system_out=text,
        system_err=text,
    )


def _parse(data: bytes) -> etree._Element:
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=True)
    return etree.fromstring(data, parser)


def _written(suite: Suite) -> etree._Element:
    """The canonical file of ``suite``, failing unless our schema and junit-10's rules take it."""
    root = _parse(serialise.serialize(suite))
    assert validate.problems(root) == []
    assert jenkins_junit10.rejections(root) == []
    return root


def _case(root: etree._Element, name: str) -> etree._Element:
    [node] = [node for node in root.iter("testcase") if node.get("name") == name]
    return node


def _tags(node: etree._Element) -> list[str]:
    return [str(child.tag) for child in node]


def _attempts(node: etree._Element) -> list[etree._Element]:
    return [child for child in node if child.tag in ATTEMPT_TAGS]


def _counts(root: etree._Element) -> tuple[str | None, ...]:
    suite = root.find("testsuite")
    assert suite is not None
    return tuple(suite.get(key) for key in ("tests", "failures", "errors", "skipped"))


def _properties(root: etree._Element) -> dict[str, str]:
    return {str(node.get("name")): str(node.get("value")) for node in root.iter("property")}


# --- the two shapes of the issue ---------------------------------------------------------------


def test_a_case_that_fails_then_passes_has_a_flaky_failure_and_no_failure() -> None:
    first = _suite([_failed(message="late node")])
    root = _written(merge_attempts([first, _suite([_passed()])]))
    node = _case(root, "a")
    assert _tags(node) == ["system-out", "flakyFailure"]
    (flaky,) = _attempts(node)
    assert (flaky.get("message"), flaky.get("type")) == ("late node", "AssertionError")
    assert flaky.findtext("stackTrace") == "Traceback: late node"
    assert flaky.findtext("system-out") == "out of late node"
    # A flaky pass counts as passed: no failure anywhere, and the suite did not fail.
    assert _counts(root) == ("1", "0", "0", "0")
    assert root.find(".//failure") is None
    assert _properties(root)["attempts"] == "2"
    assert _properties(root)["flaky_cases"] == "1"
    assert not validate.render(merge_attempts([first, _suite([_passed()])])).failed


def test_control_without_the_merge_the_last_attempt_alone_keeps_no_history() -> None:
    """The flaky element comes from the merge, not from the serialiser of a passed case."""
    root = _written(_suite([_passed()]))
    assert _tags(_case(root, "a")) == []


@pytest.mark.parametrize("reruns", [0, 1, 3])
def test_a_case_failing_every_time_keeps_all_attempts(reruns: int) -> None:
    attempts = [_suite([_failed(message=f"attempt {n}")]) for n in range(1, reruns + 2)]
    merged = merge_attempts(attempts)
    root = _written(merged)
    node = _case(root, "a")
    assert _tags(node) == ["failure"] + ["rerunFailure"] * reruns + ["system-out"]
    # The failure is the last attempt's; the reruns are the earlier ones, oldest first.
    assert node[0].get("message") == f"attempt {reruns + 1}"
    messages = [child.get("message") for child in node.iter("rerunFailure")]
    assert messages == [f"attempt {n}" for n in range(1, reruns + 1)]
    assert len(node) - 1 == reruns + 1  # N+1 attempts on record (failure + N rerun*)
    assert _counts(root) == ("1", "1", "0", "0")
    assert _properties(root)["attempts"] == str(reruns + 1)
    assert _properties(root)["flaky_cases"] == "0"
    assert validate.render(merged).failed


def test_errors_and_failures_keep_their_kind() -> None:
    error = Outcome.ERROR
    flaky = merge_attempts(
        [_suite([_failed(outcome=error)]), _suite([_failed()]), _suite([_passed()])]
    )
    assert _tags(_case(_written(flaky), "a")) == ["system-out", "flakyError", "flakyFailure"]
    rerun = merge_attempts(
        [_suite([_failed(outcome=error)]), _suite([_failed()]), _suite([_failed(outcome=error)])]
    )
    root = _written(rerun)
    assert _tags(_case(root, "a")) == ["error", "rerunError", "rerunFailure", "system-out"]
    assert _counts(root) == ("1", "0", "1", "0")


def test_a_failure_after_a_pass_is_a_failure_with_the_earlier_failures_only() -> None:
    attempts = [_suite([_failed(message="one")]), _suite([_passed()]), _suite([_failed()])]
    node = _case(_written(merge_attempts(attempts)), "a")
    assert _tags(node) == ["failure", "rerunFailure", "system-out"]
    assert node[1].get("message") == "one"


def test_a_case_that_passed_every_time_has_no_attempts_and_the_others_are_counted() -> None:
    attempts = [
        _suite([_passed("steady"), _failed("wobbly"), _passed("skip")]),
        _suite(
            [_passed("steady"), _passed("wobbly"), Case(CLASS, "skip", outcome=Outcome.SKIPPED)]
        ),
    ]
    root = _written(merge_attempts(attempts))
    assert _tags(_case(root, "steady")) == []
    assert _tags(_case(root, "wobbly")) == ["system-out", "flakyFailure"]
    assert _tags(_case(root, "skip")) == ["skipped"]
    assert _counts(root) == ("3", "0", "0", "1")


def test_a_skipped_case_after_a_failure_is_flaky_and_skipped() -> None:
    skipped = Case(CLASS, "a", outcome=Outcome.SKIPPED, message="no GPU")
    merged = merge_attempts([_suite([_failed()]), _suite([skipped])])
    root = _written(merged)
    assert _tags(_case(root, "a")) == ["skipped", "flakyFailure"]
    assert merged.cases[0].flaky
    assert _counts(root) == ("1", "0", "0", "1")


# --- cases that come and go --------------------------------------------------------------------


def test_a_case_absent_from_the_last_attempt_is_kept_skipped_with_its_failures() -> None:
    """The runner's own case of a timed-out first attempt, then the test's real cases.

    As ``ResultFile.case`` makes it: in the suite's own class, named after the test.
    """
    timeout = Case.saying("pkg.test", "test", Outcome.FAILURE, "The test timed out after 60 s")
    first = _suite([timeout], system_out="console of the first attempt")
    merged = merge_attempts([first, _suite([_passed("real")])])
    root = _written(merged)
    assert [node.get("name") for node in root.iter("testcase")] == ["real", "test"]
    node = _case(root, "test")
    assert _tags(node) == ["skipped", "flakyFailure"]
    expected = ABSENT.format(total=2, seen=1, outcome="failure")
    assert node[0].get("message") == expected
    assert node[1].get("message") == "The test timed out after 60 s"
    # The lone case of an attempt takes the attempt's console: where the runner put it.
    assert node[1].findtext("system-out") == "console of the first attempt"
    assert _counts(root) == ("2", "0", "0", "1")
    assert not merged.failed


@pytest.mark.parametrize("outcome", [Outcome.FAILURE, Outcome.ERROR])
def test_a_test_case_that_failed_and_then_was_not_run_stays_failed(outcome: Outcome) -> None:
    """Issue 30, item 5: no attempt after its failure ran it, so it never passed."""
    first = _suite([_failed("a", "boom", outcome), _passed("b")])
    merged = merge_attempts([first, _suite([_passed("b")])])
    root = _written(merged)
    node = _case(root, "a")
    assert _tags(node) == [outcome.value, f"rerun{outcome.value.title()}"]
    assert node[0].get("message") == NOT_RUN_AGAIN.format(total=2, seen=1, outcome=outcome.value)
    assert node[0].get("message", "").startswith("Failed, then not run: ")
    assert node[0].get("type") == NOT_RUN_AGAIN_TYPE
    assert node[1].get("message") == "boom"  # the failure itself, kept as the attempt
    failures, errors = (1, 0) if outcome is Outcome.FAILURE else (0, 1)
    assert _counts(root) == ("2", str(failures), str(errors), "0")
    assert merged.failed and validate.render(merged).failed
    assert not merged.cases[1].flaky
    assert _properties(root)["flaky_cases"] == "0"


def test_control_the_same_case_run_again_and_passing_is_a_flaky_pass() -> None:
    first = _suite([_failed("a", "boom"), _passed("b")])
    merged = merge_attempts([first, _suite([_passed("b"), _passed("a")])])
    assert _tags(_case(_written(merged), "a")) == ["system-out", "flakyFailure"]
    assert not merged.failed


def test_a_case_that_passed_after_failing_and_then_was_not_run_is_skipped() -> None:
    """Its last run passed: not a failure, and not a pass of the last attempt either."""
    attempts = [_suite([_failed("a"), _passed("b")]), _suite([_passed("a"), _passed("b")])]
    merged = merge_attempts([*attempts, _suite([_passed("b")])])
    node = _case(_written(merged), "a")
    assert _tags(node) == ["skipped", "flakyFailure"]
    assert node[0].get("message") == ABSENT.format(total=3, seen=2, outcome="passed")
    assert not merged.failed


def test_the_runners_own_cases_about_an_attempt_are_answered_by_a_later_one(
    tmp_path: Path,
) -> None:
    """The exit, a damaged file, a lost output file: attempt 1's, its ending passed later.

    Made as the runner makes them, in the suite's own class; the same names in a class
    of the test's own stay failed.
    """
    (tmp_path / "test.xml").write_text("this is not xml\n")
    damaged = normalise.damage_case(reader.read(tmp_path / "test.xml"), "pkg", "test")
    exit_case = normalise.exit_case("pkg.test", "exited with code 1", all_passed=True)
    output = Case.saying("pkg.test", "output file", Outcome.ERROR, "No space left on device")
    own = [damaged, exit_case, output]
    merged = merge_attempts([_suite([*own, _passed("b")]), _suite([_passed("b")])])
    root = _written(merged)
    for name in ("result file", "test process exit", "output file"):
        assert _tags(_case(root, name))[0] == "skipped", name
    assert not merged.failed
    theirs = [Case.saying(CLASS, case.name, case.outcome, case.message) for case in own]
    again = merge_attempts([_suite([*theirs, _passed("b")]), _suite([_passed("b")])])
    assert _counts(_written(again)) == ("4", "1", "2", "0")


def test_a_passed_case_absent_from_the_last_attempt_is_kept_skipped_without_attempts() -> None:
    attempts = [_suite([_passed("gone"), _failed("a")]), _suite([_passed("a")])]
    root = _written(merge_attempts(attempts))
    node = _case(root, "gone")
    assert _tags(node) == ["skipped"]
    assert node[0].get("message") == ABSENT.format(total=2, seen=1, outcome="passed")
    # A multi-case attempt's console is not pinned on one of its cases.
    assert _attempts(_case(root, "a"))[0].find("system-out") is not None  # the case's own output
    lone_output = merge_attempts(
        [_suite([_failed("a"), _passed("b")], system_out="console"), _suite([_passed("a")])]
    )
    assert "console" not in serialise.serialize(lone_output).decode()


def test_a_flaky_pass_opens_with_its_output_saying_so_once_however_often_re_read() -> None:
    """xunit-viewer takes a case's status from its first child: an attempt there reads "?"."""
    case = _passed()
    case.system_out = "the test's own output"
    case.attempts = [Attempt("flakyFailure", "first try")]
    node = _case(_written(_suite([case])), "a")
    assert _tags(node) == ["system-out", "flakyFailure"]
    note = "Passed after 1 failed attempt(s); each is recorded below."
    assert node.findtext("system-out") == f"{note}\nthe test's own output"
    # Written again from what a reader gets back: the line is not added twice.
    case.system_out = str(node.findtext("system-out"))
    again = _case(_written(_suite([case])), "a")
    assert again.findtext("system-out") == f"{note}\nthe test's own output"


def test_a_case_that_appears_in_a_later_attempt_has_no_history() -> None:
    attempts = [_suite([_failed("a")]), _suite([_failed("a"), _passed("b")])]
    root = _written(merge_attempts(attempts))
    assert _tags(_case(root, "b")) == []
    assert _tags(_case(root, "a")) == ["failure", "rerunFailure", "system-out"]


def test_a_case_seen_in_some_earlier_attempts_only_keeps_those_failures() -> None:
    attempts = [
        _suite([_failed("a", "first")]),
        _suite([_passed("b")]),
        _suite([_failed("a", "third"), _passed("b")]),
        _suite([_passed("a"), _passed("b")]),
    ]
    node = _case(_written(merge_attempts(attempts)), "a")
    assert [child.get("message") for child in _attempts(node)] == ["first", "third"]


# --- what the merged suite says about the run --------------------------------------------------


def test_properties_keep_each_earlier_attempts_differing_values() -> None:
    attempts = [
        _suite([_failed()], properties={"ros_domain_id": "3", "command": "t", "exit_code": "1"}),
        _suite([_passed()], properties={"ros_domain_id": "8", "command": "t", "exit_code": "0"}),
    ]
    properties = _properties(_written(merge_attempts(attempts)))
    assert properties["ros_domain_id"] == "8"
    assert properties["attempt_1.ros_domain_id"] == "3"
    assert properties["attempt_1.exit_code"] == "1"
    assert "attempt_1.command" not in properties  # the same in every attempt: said once
    assert properties["attempts"] == "2"


def test_suite_time_is_every_attempts_and_the_timestamp_the_first() -> None:
    first = _suite([_failed()], time=2.0, timestamp="2026-01-01T10:00:00")
    last = _suite([_passed()], time=3.5, timestamp="2026-01-01T10:00:09")
    merged = merge_attempts([first, last])
    assert (merged.time, merged.timestamp) == (5.5, "2026-01-01T10:00:00")


def test_a_single_attempt_is_itself_with_the_attempt_count() -> None:
    suite = _suite([_failed(), _passed("b")], properties={"exit_code": "1"})
    merged = merge_attempts([suite])
    assert [case.attempts for case in merged.cases] == [[], []]
    assert merged.properties == {"exit_code": "1", "attempts": "1", "flaky_cases": "0"}


def test_no_attempt_is_a_programming_error() -> None:
    with pytest.raises(ValueError, match="at least one attempt"):
        merge_attempts([])


def test_the_inputs_are_not_changed() -> None:
    first, last = _suite([_failed()]), _suite([_passed()], properties={"x": "1"})
    merge_attempts([first, last])
    assert last.cases[0].attempts == [] and last.properties == {"x": "1"}


def test_a_producers_own_attempts_are_kept_in_order_and_renamed_for_the_final_outcome() -> None:
    """pytest-rerunfailures inside one attempt: its reruns come before that attempt's end."""
    inner = _failed(message="second try")
    inner.attempts = [Attempt("rerunFailure", "first try", "E")]
    last = _passed()
    last.attempts = [Attempt("flakyError", "third try", "E")]
    node = _case(_written(merge_attempts([_suite([inner]), _suite([last])])), "a")
    assert _tags(node) == ["system-out", "flakyFailure", "flakyFailure", "flakyError"]
    assert [child.get("message") for child in _attempts(node)] == [
        "first try",
        "second try",
        "third try",
    ]


def test_for_outcome_names_attempts_for_a_failed_or_a_passed_end() -> None:
    attempts = [Attempt("flakyError"), Attempt("rerunFailure")]
    assert [a.kind for a in for_outcome(attempts, Outcome.FAILURE)] == [
        "rerunError",
        "rerunFailure",
    ]
    assert [a.kind for a in for_outcome(attempts, Outcome.PASSED)] == [
        "flakyError",
        "flakyFailure",
    ]


def test_an_unknown_attempt_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="not one of"):
        Attempt("failure")


# --- type, message and text as junit-10 wants them ----------------------------------------------


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
    node = _case(_written(_suite([case])), "a")
    [attempt] = node.iter(kind)
    assert attempt.get("type") == (expected if given != "\x00\n" else "\\x00")


def test_an_attempt_without_text_has_its_message_as_stack_trace_and_without_both_is_empty() -> None:
    case = _passed()
    case.attempts = [Attempt("flakyFailure", "only a message"), Attempt("flakyFailure")]
    first, second = _attempts(_case(_written(_suite([case])), "a"))
    assert first.findtext("stackTrace") == "only a message"
    assert (len(second), second.get("message")) == (0, "")


def test_hostile_attempt_values_stay_valid_and_read_back() -> None:
    value = 'quote " amp & lt < ]]> \x1b[31mred\x1b[0m \x01 tab\tcr\r \ud800 robot \U0001f916'
    case = _passed()
    case.attempts = [Attempt("flakyFailure", value, value, value, value, value)]
    (attempt,) = _attempts(_case(_written(_suite([case])), "a"))
    shown = 'quote " amp & lt < ]]> red \\x01 tab\tcr\r \\ud800 robot \U0001f916'
    assert attempt.get("message") == shown
    assert attempt.findtext("stackTrace") == shown
    assert attempt.findtext("system-err") == shown


# --- bounds: reruns cannot blow up the file ------------------------------------------------------


def test_each_attempts_text_is_bounded_keeping_both_ends() -> None:
    big = "BEGIN" + "x" * (4 * TEXT_LIMIT) + "END"
    attempts = [_suite([_huge(big)])]
    root = _written(merge_attempts([*attempts, _suite([_passed()])]))
    (flaky,) = _attempts(_case(root, "a"))
    for value in (
        flaky.get("message"),
        flaky.findtext("stackTrace"),
        flaky.findtext("system-out"),
        flaky.findtext("system-err"),
    ):
        assert value is not None
        assert value.startswith("BEGIN") and value.endswith("END")
        assert "characters cut" in value
        assert len(value) < ATTEMPT_TEXT_LIMIT + 100


def test_only_the_oldest_and_newest_attempts_are_kept_and_the_cut_is_said() -> None:
    count = 50
    attempts = [_suite([_failed(message=f"attempt {n}")]) for n in range(1, count + 1)]
    merged = merge_attempts(attempts)
    assert len(merged.cases[0].attempts) == count - 1  # the model keeps all
    node = _case(_written(merged), "a")
    reruns = list(node.iter("rerunFailure"))
    assert len(reruns) == ATTEMPTS_KEPT
    half = ATTEMPTS_KEPT // 2
    messages = [child.get("message") for child in reruns]
    assert messages == [f"attempt {n}" for n in range(1, half + 1)] + [
        f"attempt {n}" for n in range(count - half, count)
    ]
    cut = count - 1 - ATTEMPTS_KEPT
    after_cut = reruns[half].findtext("stackTrace") or ""
    assert after_cut.startswith(f"[... {cut} more attempt(s) not kept ...]\n")
    assert after_cut.endswith(f"attempt {count - half}")
    assert _properties(_written(merged))["attempts"] == str(count)
    # Properties of earlier attempts follow the same bound.
    many = [_suite([_failed()], properties={"ros_domain_id": str(n)}) for n in range(1, count + 1)]
    kept_properties = [key for key in merge_attempts(many).properties if key.startswith("attempt_")]
    assert len(kept_properties) == ATTEMPTS_KEPT


def test_a_hundred_reruns_of_huge_output_cost_about_ten() -> None:
    big = "y" * (2 * TEXT_LIMIT)

    def size(count: int) -> int:
        attempts = [_suite([_huge(big)]) for _ in range(count)]
        return len(serialise.serialize(merge_attempts(attempts)))

    ten, hundred = size(ATTEMPTS_KEPT + 1), size(100)
    assert hundred < ten * 1.05
    # Ten attempts cost at most about the final outcome's own text and output (3 x 64 KiB).
    assert ten < 2 * 3 * TEXT_LIMIT + 3 * ATTEMPTS_KEPT * ATTEMPT_TEXT_LIMIT


def _testcases(data: bytes) -> list[bytes]:
    return [etree.tostring(node) for node in _parse(data).iter("testcase")]


@pytest.mark.parametrize("final", [Outcome.PASSED, Outcome.FAILURE])
@pytest.mark.parametrize("count", [2, ATTEMPTS_KEPT + 2, 50])
def test_a_canonical_file_normalised_again_keeps_its_cases(
    tmp_path: Path, count: int, final: Outcome
) -> None:
    """What ``ros-isolated-test normalise`` does to a file the runner wrote: nothing."""
    last = _passed() if final is Outcome.PASSED else _failed(message="last")
    history = [_suite([_failed(message=f"attempt {n}")]) for n in range(1, count)]
    canonical = serialise.serialize(merge_attempts([*history, _suite([last])]))
    source = tmp_path / "canonical.xml"
    written = canonical
    for _ in range(2):
        source.write_bytes(written)
        again, _ = normalise_file(source, "pkg", "test")
        assert _testcases(again) == _testcases(canonical)
        written = again
    node = _case(_parse(canonical), "a")
    assert len(_attempts(node)) == min(count - 1, ATTEMPTS_KEPT)
    if final is Outcome.PASSED:
        # The note says how many failed and, when some were cut, which are shown.
        shown = "each is" if count - 1 <= ATTEMPTS_KEPT else "the first 5 and the last 5 are"
        note = f"Passed after {count - 1} failed attempt(s); {shown} recorded below."
        assert node.findtext("system-out") == note


def test_a_gitlab_type_with_edge_spaces_is_caught_when_merged_as_an_attempt() -> None:
    """A canonical ``<failure type=" symbol">`` becomes an attempt, written trimmed."""
    first = _failed()
    first.type = " symbol"
    root = _written(merge_attempts([_suite([first]), _suite([_passed()])]))
    [attempt] = _attempts(_case(root, "a"))
    assert attempt.get("type") == "symbol (producer type)"
    alone = _case(_written(_suite([first])), "a").find("failure")
    assert alone is not None
    assert alone.get("type") == "symbol (producer type)"
    # Control: a type GitLab leaves alone is written as given, trimmed.
    first.type = " AssertionError "
    root = _written(merge_attempts([_suite([first]), _suite([_passed()])]))
    assert [node.get("type") for node in _attempts(_case(root, "a"))] == ["AssertionError"]


def _gitlab_keys(root: etree._Element) -> list[str]:
    return [
        f"{suite.get('name')}_{node.get('classname')}_{node.get('name')}"
        for suite in root.iter("testsuite")
        for node in suite.iter("testcase")
    ]


def test_cases_of_different_attempts_never_share_a_gitlab_key() -> None:
    """(pkg.a, b_c) only in attempt 1 and (pkg.a_b, c) in the last are two cases."""
    failing = Case("pkg.a", "b_c", outcome=Outcome.FAILURE, message="m", text="t", type="E")
    last = _suite([Case("pkg.a_b", "c")])
    merged = merge_attempts([_suite([failing, Case("pkg.a_b", "c")]), last])
    assert [(case.classname, case.name) for case in merged.cases] == [
        ("pkg.a_b", "c"),
        ("pkg.a", "b_c [2]"),
    ]
    keys = _gitlab_keys(_written(merged))
    assert len(set(keys)) == len(keys) == 2
    assert "renamed" in merged.properties[RENAMED_PROPERTY]
    # Control: cases whose keys differ keep their names and the merge reports nothing.
    other = Case("pkg.a", "b", outcome=Outcome.FAILURE, message="m", text="t", type="E")
    merged = merge_attempts([_suite([other]), last])
    assert [case.name for case in merged.cases] == ["c", "b"]
    assert RENAMED_PROPERTY not in merged.properties


def test_kept_leaves_a_short_list_alone() -> None:
    attempts = [Attempt("flakyFailure", str(n)) for n in range(ATTEMPTS_KEPT)]
    assert kept(attempts) is attempts


# --- the schema: exactly these shapes, a subset of junit-10 ---------------------------------------

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


def test_a_flaky_count_property_that_disagrees_with_the_cases_is_a_problem() -> None:
    merged = merge_attempts([_suite([_failed()]), _suite([_passed()])])
    assert validate.problems(_parse(serialise.serialize(merged))) == []
    merged.properties["flaky_cases"] = "2"
    found = validate.problems(_parse(serialise.serialize(merged)))
    assert found == ["suite pkg.test: property flaky_cases=2, cases say 1"]


def test_a_result_failing_validation_still_renders_valid_without_a_wrong_flaky_count() -> None:
    merged = merge_attempts([_suite([_failed()]), _suite([_passed()])])
    merged.properties["flaky_cases"] = "7"
    rendered = validate.render(merged)
    root = _parse(rendered.data)
    assert validate.problems(root) == []
    assert rendered.failed  # the internal error says the result was ours to get right
    assert "flaky_cases" not in _properties(root)


def test_the_layout_with_attempts_is_lxmls_pretty_print() -> None:
    merged = merge_attempts(
        [_suite([_failed(), _failed("b")]), _suite([_passed(), _failed("b", "again")])]
    )
    data = serialise.serialize(merged)
    again = etree.tostring(_parse(data), xml_declaration=True, encoding="UTF-8", pretty_print=True)
    assert data == again


def _random_history(rng: random.Random) -> list[Suite]:
    outcomes = list(Outcome)
    names = ["a", "b", "c", "d"]
    attempts = []
    for _ in range(rng.randint(1, 6)):
        cases = []
        for name in rng.sample(names, rng.randint(0, len(names))):
            outcome = rng.choice(outcomes)
            case = Case(CLASS, name, outcome=outcome, message=rng.choice(["", "m", " "]))
            case.type = rng.choice(["", "T", " "])
            case.attempts = [
                Attempt(rng.choice(("flakyFailure", "rerunError")), "inner")
                for _ in range(rng.randint(0, 2))
            ]
            case.attempts = for_outcome(case.attempts, outcome)
            cases.append(case)
        attempts.append(_suite(cases, system_out=rng.choice(["", "console"])))
    return attempts


def test_random_histories_always_merge_into_valid_files_with_honest_counts() -> None:
    rng = random.Random(14)
    for _ in range(300):
        attempts = _random_history(rng)
        merged = merge_attempts(attempts)
        root = _written(merged)
        # A case the last attempt lacks: failed if it failed when last seen, else skipped.
        seen = {case.name: case.outcome for suite in attempts for case in suite.cases}
        seen = {name: value if value.failed else Outcome.SKIPPED for name, value in seen.items()}
        last = seen | {case.name: case.outcome for case in attempts[-1].cases}
        for node in root.iter("testcase"):
            tags = _tags(node)
            outcome = last[str(node.get("name"))]
            finals = [tag for tag in tags if tag in ("failure", "error", "skipped")]
            assert finals == ([] if outcome is Outcome.PASSED else [outcome.value]), tags
            prefix = "rerun" if outcome.failed else "flaky"
            assert all(tag.startswith(prefix) for tag in tags if tag in ATTEMPT_TAGS), tags
        flaky = sum(1 for case in merged.cases if case.flaky)
        assert _properties(root)["flaky_cases"] == str(flaky)
        assert _properties(root)["attempts"] == str(len(attempts))


# --- the outside tier: the real junit-10.xsd ----------------------------------------------------


@pytest.fixture(scope="module")
def junit10_xsd() -> Iterator[etree.XMLSchema]:
    """The schema Jenkins' xunit-plugin validates "JUnit" input with."""
    capabilities.require(capabilities.OUTSIDE)
    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    yield etree.XMLSchema(etree.parse(str(capabilities.JENKINS_JUNIT10_XSD), parser))


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


@capabilities.OUTSIDE
def test_real_junit10_accepts_every_merged_file(junit10_xsd: etree.XMLSchema) -> None:
    rng = random.Random(10)
    for _ in range(200):
        root = _written(merge_attempts(_random_history(rng)))
        assert junit10_xsd.validate(root), junit10_xsd.error_log
    big = [_suite([_failed(message="x" * 3 * TEXT_LIMIT)]) for _ in range(30)]
    assert junit10_xsd.validate(_written(merge_attempts(big))), junit10_xsd.error_log
