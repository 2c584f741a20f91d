"""``xunit.normalise``: what a test left behind, turned into canonical cases, one rule at a time.

Each producer gets something wrong for some reader; the fixes are generic where they
can be and keyed to a producer's shape where not. Here each rule on the raw model
directly (the package prefix once, times read as producers write them, nameless
failures named, duplicates merged to the worst outcome, a cut-off case an error, cases
beyond the bound summed up, nothing run said); ``test_normalise_readers`` checks the
rules each reader needs on whole files, and ``tests/e2e/test_normalise_samples.py``
(with the real samples) says what is odd in each producer's file.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import pytest

from ros_isolated_test.xunit import normalise
from ros_isolated_test.xunit.model import Attempt, Case, Outcome
from ros_isolated_test.xunit.raw import RawCase, RawOutcome, RawSuite, ReadResult


def _read(*cases: RawCase, **fields: object) -> ReadResult:
    """A file that was read as a ``<testsuite>`` holding ``cases``."""
    read = ReadResult(Path("t.xml"), root_tag="testsuite", cases=list(cases))
    for name, value in fields.items():
        setattr(read, name, value)
    return read


def _raw(name: str, classname: str = "C", *outcomes: RawOutcome, suite: str = "s") -> RawCase:
    return RawCase({"name": name, "classname": classname}, suite, list(outcomes))


def _outcomes(cases: list[Case]) -> list[tuple[str, str, Outcome]]:
    return [(case.classname, case.name, case.outcome) for case in cases]


def test_the_package_prefix_is_added_exactly_once() -> None:
    assert normalise.prefixed("pkg", "C") == "pkg.C"
    assert normalise.prefixed("pkg", "pkg.C") == "pkg.C"
    assert normalise.prefixed("pkg", "pkgx.C") == "pkg.pkgx.C"
    assert normalise.prefixed(None, "C") == "C"


@pytest.mark.parametrize(
    ("written", "seconds"),
    [("0.", 0.0), ("1,234.5", 1234.5), (" 2.5 ", 2.5), ("3", 3.0), ("", 0.0), (None, 0.0)]
    + [(nonsense, 0.0) for nonsense in ("abc", "-1", "nan", "inf", "1e999")],
)
def test_a_producers_time_reads_as_seconds_and_nonsense_as_zero(
    written: str | None, seconds: float
) -> None:
    found = normalise.seconds(written)
    assert found == seconds and math.isfinite(found)


def test_a_case_gets_the_package_prefix_and_the_test_name_where_the_producer_gave_none() -> None:
    cases = normalise.cases_from(
        _read(_raw("a"), _raw("b", ""), _raw("c", "pkg"), _raw("", "C")), "pkg", "talker"
    )
    assert _outcomes(cases) == [
        ("pkg.C", "a", Outcome.PASSED),
        ("pkg.s", "b", Outcome.PASSED),  # no class name: the suite's
        ("pkg.talker", "c", Outcome.PASSED),  # the package alone: ament's own results
        ("pkg.C", "unnamed test case 4", Outcome.PASSED),
    ]


def test_gtests_nameless_failures_are_named_for_what_failed() -> None:
    failure = RawOutcome("failure", {"message": "SetUp failed"}, "trace")
    cases = normalise.cases_from(
        _read(
            _raw("", "", failure, suite="NonTestSuiteFailure"),
            _raw("", "pkg.", failure, suite="Suite1"),
        ),
        "pkg",
        "t",
    )
    assert _outcomes(cases) == [
        ("pkg.NonTestSuiteFailure", "global environment set-up or tear-down", Outcome.FAILURE),
        ("pkg.Suite1", "suite set-up or tear-down", Outcome.FAILURE),
    ]
    assert cases[0].message == "SetUp failed" and cases[0].text == "trace"


def test_the_worst_outcome_wins_and_every_message_is_kept() -> None:
    error = RawOutcome("error", {"message": "teardown broke"}, "")
    failure = RawOutcome("failure", {"message": "assert 1 == 2", "type": "AssertionError"}, "")
    [case] = normalise.cases_from(_read(_raw("a", "C", error, failure)), "pkg", "t")
    assert (case.outcome, case.type) == (Outcome.FAILURE, "AssertionError")
    assert case.message == "assert 1 == 2\n\nteardown broke"
    assert case.text == case.message  # no text of its own: the message stands in


def test_duplicate_cases_merge_into_one_with_the_worst_outcome() -> None:
    """pytest writes a failing test with a teardown error twice; GitLab would keep one."""
    cases = [
        Case("pkg.C", "a", time=1.0),
        Case("pkg.C", "a", time=2.0, outcome=Outcome.FAILURE, message="x", text="x"),
        Case("pkg.C", "a", outcome=Outcome.ERROR, message="y", text="y"),
        Case("pkg.C", "b"),
    ]
    merged = normalise.merge_duplicates(cases)
    assert _outcomes(merged) == [("pkg.C", "a", Outcome.FAILURE), ("pkg.C", "b", Outcome.PASSED)]
    assert (merged[0].message, merged[0].time) == ("x\n\ny", 2.0)


def test_attempts_of_merged_duplicates_are_named_for_the_final_outcome() -> None:
    first = Case("pkg.C", "a", attempts=[Attempt("flakyFailure", "try 1")])
    second = Case("pkg.C", "a", outcome=Outcome.FAILURE, message="m")
    [case] = normalise.merge_duplicates([first, second])
    assert [attempt.kind for attempt in case.attempts] == ["rerunFailure"]
    [alone] = normalise.merge_duplicates([Case("pkg.C", "a", attempts=[Attempt("rerunError")])])
    assert [attempt.kind for attempt in alone.attempts] == ["rerunError"]  # not merged: as given


def test_a_disabled_test_is_skipped_not_passed() -> None:
    gtest = RawCase({"name": "DISABLED_a", "classname": "C", "result": "suppressed"}, "s")
    ctest = RawCase({"name": "b", "classname": "C", "status": "disabled"}, "s")
    ran = RawCase({"name": "c", "classname": "C", "status": "run"}, "s")
    cases = normalise.cases_from(_read(gtest, ctest, ran), "pkg", "t")
    assert [(case.outcome, case.message) for case in cases] == [
        (Outcome.SKIPPED, "disabled"),
        (Outcome.SKIPPED, "disabled"),
        (Outcome.PASSED, ""),
    ]


def test_a_case_the_file_ended_inside_is_an_error() -> None:
    cut = _raw("a")
    cut.complete = False
    cases = normalise.cases_from(_read(cut, _raw("b")), "pkg", "t")
    assert _outcomes(cases) == [("pkg.C", "a", Outcome.ERROR), ("pkg.C", "b", Outcome.PASSED)]
    assert cases[0].message == "The result file ends inside this test case."
    assert cases[0].type == "BrokenResultFile"


def test_cases_beyond_the_bound_are_one_summary_case_as_bad_as_the_worst() -> None:
    passed = normalise.cases_from(_read(_raw("a"), dropped=Counter(passed=5)), "pkg", "t")
    assert _outcomes(passed)[-1] == ("pkg.t", "further test cases", Outcome.PASSED)
    assert passed[-1].system_out.startswith("5 further test case(s) were not kept")
    worse = normalise.cases_from(_read(_raw("a"), dropped=Counter(passed=2, failure=1)), "pkg", "t")
    assert _outcomes(worse)[-1] == ("pkg.t", "further test cases", Outcome.FAILURE)
    assert worse[-1].message.endswith(": 1 failure, 2 passed")


def test_a_file_that_holds_no_case_is_one_skipped_case() -> None:
    [case] = normalise.cases_from(_read(), "pkg", "t")
    assert (case.classname, case.name, case.outcome) == ("pkg.t", "no test cases", Outcome.SKIPPED)
    assert case.type == "NoTestCases"
    assert _outcomes(normalise.cases_from(_read(_raw("a")), "pkg", "t")) == [
        ("pkg.C", "a", Outcome.PASSED)
    ]


def test_damage_is_one_error_case_saying_what_was_kept() -> None:
    read = _read(_raw("a"), problems=["not well-formed at line 3: boom"])
    cases = normalise.cases_from(read, "pkg", "t")
    assert _outcomes(cases) == [
        ("pkg.C", "a", Outcome.PASSED),
        ("pkg.t", "result file", Outcome.ERROR),
    ]
    assert cases[1].message == (
        "Invalid result file t.xml, not fully readable: not well-formed at line 3: boom. "
        "1 test case(s) before the damage were kept."
    )


def test_counts_claimed_beyond_the_cases_are_said_and_more_cases_are_not() -> None:
    claiming = _read(_raw("a"), suites=[RawSuite("s", {"tests": "3", "failures": "1"})])
    assert normalise.unreported(claiming) == [
        "2 more test case(s)",
        "1 more failure(s) or error(s)",
    ]
    duplicates = _read(_raw("a"), _raw("a"), suites=[RawSuite("s", {"tests": "1"})])
    assert normalise.unreported(duplicates) == []


def test_a_test_case_repeated_in_another_suite_is_another_run() -> None:
    """launch_testing's parametrised runs: named after their suite, kept, not merged."""
    cases = normalise.cases_from(
        _read(_raw("a", suite="run1"), _raw("a", suite="run2"), _raw("a", suite="run1")),
        "pkg",
        "t",
    )
    assert [case.name for case in cases] == ["a", "a [run2]"]


def test_the_exit_case_says_what_the_process_did_beside_its_cases() -> None:
    case = normalise.exit_case("pkg.t", "exited with code 1", all_passed=True)
    assert (case.name, case.outcome, case.type) == (
        "test process exit",
        Outcome.FAILURE,
        "ExitStatus",
    )
    assert case.message == (
        "The test process exited with code 1, although every test case it reported passed."
    )
    other = normalise.exit_case("pkg.t", "was killed by SIGSEGV", all_passed=False)
    assert other.message == other.text == "The test process was killed by SIGSEGV."
