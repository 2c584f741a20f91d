"""``launch_testing_verdicts``: what ``unittest`` recorded for a launch's cases, one verdict
per case.

launch_testing runs a launch's active tests, then its post-shutdown tests, each with
``unittest.TextTestRunner(resultclass=launch_testing.test_result.TestResult)``, and appends
the second result to the first; launch_testing_cases asks ``read`` what each case got,
and shows each failure by the exception its traceback ends with. Here real ``unittest`` cases run
exactly so, with launch_testing's own result classes (test_result.py of the outside tier's
vendored Jazzy sources, which imports nothing but ``unittest``), and every outcome is read
back: passed, failed, error, skipped, expected failure, unexpected success, subtests (the
worst, every text kept), a class fixture that failed (an error of its cases not run, or
after its last case), and a case nothing was recorded for. A result that is not
launch_testing's is a Mismatch (launch_testing_cases' one warning); the control:
launch_testing's own result of the same run reads case by case.
"""

from __future__ import annotations

import importlib.util
import io
import sys
import traceback
import types
import unittest
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities, launch_runs
from helpers.capabilities import LAUNCH_SOURCES
from helpers.commands import run_process

from ros_isolated_test.pytest_plugin.launch_testing_verdicts import (
    ERROR,
    FAILED,
    PASSED,
    SKIPPED,
    XFAILED,
    XPASSED,
    Mismatch,
    Verdict,
    as_one,
    fail_result_type,
    message,
    read,
    texts,
)

#: launch_testing's result classes, in the vendored sources.
TEST_RESULT = LAUNCH_SOURCES / "launch_testing" / "launch_testing" / "test_result.py"


class Outcomes(unittest.TestCase):
    """One case of each outcome ``unittest`` records."""

    __test__ = False  # run below as launch_testing runs it, never by pytest itself

    def test_passed(self) -> None:
        pass

    def test_failure(self) -> None:
        self.assertEqual(1, 2, "one is not two")

    def test_error(self) -> None:
        raise RuntimeError("boom in test_error")

    def test_skipped(self) -> None:
        self.skipTest("skipped on purpose")

    @unittest.expectedFailure
    def test_expected_failure(self) -> None:
        self.assertEqual(1, 2, "known to fail")

    @unittest.expectedFailure
    def test_unexpected_success(self) -> None:
        pass

    def test_subtests(self) -> None:
        for value in range(4):
            with self.subTest(value=value):
                self.assertLess(value, 2, f"subtest value {value}")


class BrokenSetUp(unittest.TestCase):
    __test__ = False

    @classmethod
    def setUpClass(cls) -> None:
        raise OSError("setUpClass could not open its device")

    def test_never_runs(self) -> None:
        pass


class BrokenTearDown(unittest.TestCase):
    __test__ = False

    @classmethod
    def tearDownClass(cls) -> None:
        raise OSError("tearDownClass could not close its device")

    def test_first(self) -> None:
        pass

    def test_last(self) -> None:
        pass


class AfterShutdown(unittest.TestCase):
    """A post-shutdown test: its result is appended to the active tests' one."""

    __test__ = False

    def test_after(self) -> None:
        pass


@pytest.fixture(scope="module")
def launch_results() -> types.ModuleType:
    """launch_testing.test_result, as the vendored Jazzy sources hold it."""
    capabilities.require(capabilities.OUTSIDE)
    spec = importlib.util.spec_from_file_location("vendored_launch_testing_result", TEST_RESULT)
    assert spec is not None and spec.loader is not None, TEST_RESULT
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _each(suite: unittest.TestSuite) -> Iterator[unittest.TestCase]:
    for test in suite:
        if isinstance(test, unittest.TestSuite):
            yield from _each(test)
        else:
            assert isinstance(test, unittest.TestCase)
            yield test


def _suite(*classes: type[unittest.TestCase]) -> unittest.TestSuite:
    loader = unittest.TestLoader()
    return unittest.TestSuite([loader.loadTestsFromTestCase(case) for case in classes])


def _run(suite: unittest.TestSuite, result_class: type[Any] | None) -> Any:
    """One suite run as launch_testing runs it (``None``: with unittest's own result)."""
    runner = unittest.TextTestRunner(stream=io.StringIO(), verbosity=2, resultclass=result_class)
    return runner.run(suite)


def run_as_launch_testing(
    result_class: type[Any],
    active: tuple[type[unittest.TestCase], ...] = (Outcomes, BrokenSetUp, BrokenTearDown),
    post_shutdown: tuple[type[unittest.TestCase], ...] = (AfterShutdown,),
) -> tuple[list[unittest.TestCase], Any]:
    """The run's cases (listed before unittest lets go of them) and its appended result."""
    suites = _suite(*active), _suite(*post_shutdown)
    cases = [case for suite in suites for case in _each(suite)]
    result = _run(suites[0], result_class)
    result.append(_run(suites[1], result_class))
    return cases, result


def _by_name(cases: list[unittest.TestCase], verdicts: list[Verdict]) -> dict[str, Verdict]:
    """Each verdict by launch_testing's name of its case (Class.method)."""
    return {
        f"{type(case).__name__}.{case._testMethodName}": v
        for case, v in zip(cases, verdicts, strict=True)
    }


def test_each_case_gets_the_verdict_unittest_recorded_for_it(
    launch_results: types.ModuleType,
) -> None:
    cases, result = run_as_launch_testing(launch_results.TestResult)
    verdicts, _after = read(cases, result)
    found = _by_name(cases, verdicts)
    assert {name: verdict.kind for name, verdict in found.items()} == {
        "Outcomes.test_error": ERROR,
        "Outcomes.test_expected_failure": XFAILED,
        "Outcomes.test_failure": FAILED,
        "Outcomes.test_passed": PASSED,
        "Outcomes.test_skipped": SKIPPED,
        "Outcomes.test_subtests": FAILED,
        "Outcomes.test_unexpected_success": XPASSED,
        "BrokenSetUp.test_never_runs": ERROR,
        "BrokenTearDown.test_first": PASSED,
        "BrokenTearDown.test_last": PASSED,
        "AfterShutdown.test_after": PASSED,  # read from the appended post-shutdown result
    }
    assert found["Outcomes.test_error"].message == "RuntimeError: boom in test_error"
    assert found["Outcomes.test_failure"].message == "AssertionError: 1 != 2 : one is not two"
    assert "in test_failure" in found["Outcomes.test_failure"].text  # the whole traceback
    assert found["Outcomes.test_skipped"].message == "skipped on purpose"
    assert found["Outcomes.test_expected_failure"].message.endswith("known to fail")
    assert "marked expectedFailure, it passed" in found["Outcomes.test_unexpected_success"].message
    assert found["Outcomes.test_passed"].message == found["Outcomes.test_passed"].text == ""


def test_subtests_fail_their_case_once_with_every_failing_texts_kept(
    launch_results: types.ModuleType,
) -> None:
    cases, result = run_as_launch_testing(launch_results.TestResult, (Outcomes,), ())
    verdicts, _after = read(cases, result)
    subtests = _by_name(cases, verdicts)["Outcomes.test_subtests"]
    assert subtests.kind == FAILED
    assert subtests.message.endswith("subtest value 2")  # the first one recorded
    assert "subtest value 2" in subtests.text and "subtest value 3" in subtests.text
    assert "subtest value 1" not in subtests.text  # the control: a passing subtest says nothing


def test_a_class_fixture_that_failed_is_the_error_of_its_cases_not_run_or_after_its_last(
    launch_results: types.ModuleType,
) -> None:
    """setUpClass: its cases never ran, each gets its error. tearDownClass: its cases ran and
    keep their pass; the error is reported after the class's last case, and only there."""
    cases, result = run_as_launch_testing(launch_results.TestResult)
    verdicts, after = read(cases, result)
    found = _by_name(cases, verdicts)
    never = found["BrokenSetUp.test_never_runs"]
    assert never.message == (
        f"setUpClass ({__name__}.BrokenSetUp): OSError: setUpClass could not open its device"
    )
    assert "Traceback (most recent call last)" in never.text
    last = list(found).index("BrokenTearDown.test_last")
    assert list(after) == [last], after
    (said,) = after[last]
    assert said.startswith(f"tearDownClass ({__name__}.BrokenTearDown):\n"), said
    assert said.rstrip().endswith("OSError: tearDownClass could not close its device"), said
    # The control: the cases that ran keep what was recorded for them.
    ran = ("BrokenTearDown.test_first", "BrokenTearDown.test_last", "AfterShutdown.test_after")
    assert [found[name].kind for name in ran] == [PASSED] * 3


def test_a_case_nothing_was_recorded_for_is_an_error(launch_results: types.ModuleType) -> None:
    """Cases are matched by identity: a case of the same name that never ran is no pass."""
    cases, result = run_as_launch_testing(launch_results.TestResult, (Outcomes,), ())
    never_ran = Outcomes("test_passed")
    verdicts, _after = read([*cases, never_ran], result)
    assert (verdicts[-1].kind, verdicts[-1].message) == (
        ERROR,
        "launch_testing recorded no result for this case",
    )
    ran = [
        v
        for case, v in zip(cases, verdicts[: len(cases)], strict=True)
        if case.id() == never_ran.id()
    ]
    assert [v.kind for v in ran] == [PASSED]  # the control: the case that ran


def test_a_result_that_is_not_launch_testings_is_a_mismatch(
    launch_results: types.ModuleType,
) -> None:
    """unittest's own result keeps no list of the cases that ran: never guessed, refused."""
    suite = _suite(Outcomes)
    cases = list(_each(suite))
    plain = _run(suite, None)
    with pytest.raises(Mismatch, match="its test result has no testCases"):
        read(cases, plain)
    with pytest.raises(Mismatch, match="no testCases, errors, failures, skipped"):
        read(cases, object())
    cases, result = run_as_launch_testing(launch_results.TestResult)  # the control
    verdicts, _after = read(cases, result)
    assert len(verdicts) == len(cases)


def test_as_one_reads_a_run_as_launch_testings_own_item_does(
    launch_results: types.ModuleType,
) -> None:
    """One verdict for the run: passed, or failed with each record under its case's name;
    a launch that stopped early (launch_testing's FailResult) fails with its message."""
    _cases, passing = run_as_launch_testing(launch_results.TestResult, (AfterShutdown,), ())
    assert as_one(passing).kind == PASSED
    _cases, failing = run_as_launch_testing(launch_results.TestResult)
    verdict = as_one(failing)
    assert (verdict.kind, verdict.message) == (FAILED, "some test cases have failed")
    assert f"test_error ({__name__}.Outcomes.test_error):\n" in verdict.text
    assert "AssertionError: 1 != 2 : one is not two" in verdict.text
    cases = list(_each(_suite(Outcomes)))
    test_run = types.SimpleNamespace(all_cases=lambda: cases)  # what FailResult reads of it
    stopped = as_one(launch_results.FailResult(test_run, "processes under test died"))
    assert stopped.kind == FAILED
    assert "processes under test died" in stopped.text


def _formatted_chain() -> str:
    """A real traceback of one exception raised while handling another."""
    try:
        try:
            raise FileNotFoundError("no such map")
        except FileNotFoundError as cause:
            raise RuntimeError("could not load\nthe second line") from cause
    except RuntimeError as error:
        return "".join(traceback.format_exception(error))


def test_message_is_the_exception_a_traceback_ends_with() -> None:
    text = _formatted_chain()
    assert "FileNotFoundError: no such map" in text  # the cause is in the text ...
    assert message(text) == "RuntimeError: could not load\nthe second line"  # ... not the message
    assert message("  skipped on purpose\n") == "skipped on purpose"  # no traceback: all of it


def test_texts_names_each_record_only_when_there_are_several() -> None:
    assert texts([("case_a", "text a")]) == "text a"
    assert texts([("case_a", "text a"), ("case_b", "text b")]) == "case_a:\ntext a\ncase_b:\ntext b"


def test_the_worse_of_two_verdicts_wins_and_both_texts_are_kept() -> None:
    ranked = [PASSED, SKIPPED, XFAILED, XPASSED, FAILED, ERROR]
    for index, better in enumerate(ranked):
        for worse in ranked[index:]:
            one = Verdict(better, f"{better} message", f"{better} text")
            other = Verdict(worse, f"{worse} message", f"{worse} text")
            for joined in (one.worse(other), other.worse(one)):
                assert (joined.kind, joined.message) == (worse, f"{worse} message")
                assert joined.text == f"{worse} text\n{better} text"
    assert Verdict(PASSED).worse(Verdict(FAILED, "m", "t")).text == "t"  # no empty line


def test_fail_result_type_is_a_mismatch_where_launch_testing_is_missing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(sys.modules, "launch_testing", None)  # any import of it fails
    monkeypatch.setitem(sys.modules, "launch_testing.test_result", None)
    with pytest.raises(Mismatch, match=r"launch_testing\.test_result\.FailResult is missing"):
        fail_result_type()


#: In the launch environment: whether fail_result_type() finds launch_testing's own class.
FINDS_FAIL_RESULT = """\
import launch_testing.test_result
from ros_isolated_test.pytest_plugin.launch_testing_verdicts import fail_result_type
print(fail_result_type() is launch_testing.test_result.FailResult)
"""


def test_control_fail_result_type_is_launch_testings_own_where_it_is_installed(
    tmp_path: Path, env: dict[str, str]
) -> None:
    python = launch_runs.launch_python()
    done = run_process([str(python), "-c", FINDS_FAIL_RESULT], env, cwd=tmp_path)
    assert (done.returncode, done.stdout) == (0, "True\n"), done.stderr
