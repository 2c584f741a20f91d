"""``xunit.model``: the canonical result as data, and the few rules the data itself keeps.

Outcomes are ordered so merging takes the worst; an attempt's kind is one of Surefire's
four; flaky means passed after a failure; counts are recomputed from the cases.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from ros_isolated_test.xunit.model import ATTEMPT_KINDS, Attempt, Case, Outcome, Suite


def _suite(*cases: Case) -> Suite:
    return Suite("pkg.test", list(cases), 0.0, "2026-01-01T00:00:00", "host")


def test_outcomes_rank_from_passed_to_failure() -> None:
    ranked = sorted(Outcome, key=lambda outcome: outcome.rank)
    assert ranked == [Outcome.PASSED, Outcome.SKIPPED, Outcome.ERROR, Outcome.FAILURE]
    assert max([Outcome.ERROR, Outcome.PASSED, Outcome.SKIPPED], key=lambda o: o.rank) is (
        Outcome.ERROR
    )


def test_only_error_and_failure_fail() -> None:
    assert {outcome for outcome in Outcome if outcome.failed} == {Outcome.ERROR, Outcome.FAILURE}


def test_an_attempt_kind_outside_surefires_four_is_refused() -> None:
    for kind in ATTEMPT_KINDS:  # the control: each of the four is taken
        assert Attempt(kind).kind == kind
    with pytest.raises(ValueError, match="flakySkip"):
        Attempt("flakySkip")


def test_flaky_is_passed_after_a_flaky_attempt() -> None:
    assert Case("pkg.C", "t", attempts=[Attempt("flakyFailure")]).flaky
    assert Case("pkg.C", "t", outcome=Outcome.SKIPPED, attempts=[Attempt("flakyError")]).flaky
    assert not Case("pkg.C", "t").flaky, "no attempt: a plain pass"
    failed = Case("pkg.C", "t", outcome=Outcome.FAILURE, attempts=[Attempt("flakyFailure")])
    assert not failed.flaky, "a case that failed in the end is a failure, not a flake"
    assert not Case("pkg.C", "t", attempts=[Attempt("rerunFailure")]).flaky


def test_a_case_of_the_runners_own_says_its_message_as_text() -> None:
    case = Case.saying("pkg.t", "result file", Outcome.ERROR, "no result file", "NoResult")
    assert (case.message, case.text, case.type) == ("no result file", "no result file", "NoResult")
    assert case.outcome is Outcome.ERROR
    plain = Case("pkg.t", "result file", outcome=Outcome.ERROR, message="no result file")
    assert plain.text == "", "the control: a plain case's text is its own"


def test_cases_and_suites_never_share_a_default_list() -> None:
    first, second = Case("pkg.C", "a"), Case("pkg.C", "b")
    first.attempts.append(Attempt("flakyFailure"))
    assert second.attempts == []
    one, other = _suite(), _suite()
    one.properties["key"] = "value"
    assert other.properties == {}


def test_counts_are_recomputed_from_the_cases() -> None:
    case = Case("pkg.C", "a")
    suite = _suite(case, Case("pkg.C", "b", outcome=Outcome.SKIPPED))
    assert (suite.count(Outcome.PASSED), suite.count(Outcome.SKIPPED)) == (1, 1)
    assert not suite.failed
    case.outcome = Outcome.FAILURE
    assert (suite.count(Outcome.PASSED), suite.count(Outcome.FAILURE)) == (0, 1)
    assert suite.failed


def test_an_error_fails_the_suite_and_a_skip_does_not() -> None:
    assert _suite(Case("pkg.C", "a", outcome=Outcome.ERROR)).failed
    assert not _suite(Case("pkg.C", "a", outcome=Outcome.SKIPPED)).failed
    assert not _suite().failed, "no cases: nothing failed"


def test_importing_the_model_loads_no_dataclasses() -> None:
    """The module's reason for plain classes: it is on every test's path."""
    probe = "import sys, {module}; print('dataclasses' in sys.modules)"
    found = [
        subprocess.run(
            [sys.executable, "-c", probe.format(module=module)],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
        for module in (
            "ros_isolated_test.xunit.model",
            "ros_isolated_test.xunit.model, dataclasses",
        )
    ]
    # The control: the probe sees dataclasses when something does load them.
    assert found == ["False", "True"]


def test_an_unknown_attempt_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="not one of"):
        Attempt("failure")
