"""``exit_codes``: the rules, one at a time: how a test's end becomes a code and a result file.

The end-to-end paths (real processes) are in the tests of the CLI's ``run``, of the ament
contract and of exit reconciliation, and ``verdict`` applies these rules
(test_verdict.py); here each rule is checked over the values it decides on.
"""

from __future__ import annotations

import signal

import pytest

from ros_isolated_test.process.supervisor import Outcome
from ros_isolated_test.runner import exit_codes as rules


def test_how_the_test_ended() -> None:
    assert rules.ended(Outcome(0, 1.0), ament=False, timeout=None) == (0, "exited with code 0")
    assert rules.ended(Outcome(None, 0.0, start_error=FileNotFoundError(2, "x")), False, None)[
        0
    ] == (rules.NOT_FOUND)
    assert rules.ended(Outcome(None, 0.0, start_error=PermissionError(13, "x")), False, None)[
        0
    ] == (rules.NOT_EXECUTABLE)
    assert rules.ended(Outcome(None, 0.0, start_error=FileNotFoundError(2, "x")), True, None)[
        0
    ] == (rules.FAILED)
    code, reason = rules.ended(Outcome(-11, 1.0), False, None)
    assert (code, reason) == (139, "was killed by SIGSEGV (signal 11)")
    code, reason = rules.ended(Outcome(-15, 2.0, timed_out=True), False, 2.0)
    assert code == rules.TIMEOUT and "--timeout 2" in reason
    code, reason = rules.ended(Outcome(0, 1.0, received_signal=int(signal.SIGINT)), False, None)
    assert code == 130 and "received SIGINT" in reason


@pytest.mark.parametrize(
    ("code", "skip", "generate", "own", "shell", "written"),
    [
        (0, False, True, False, True, rules.WRITE_PASSED),
        (0, False, True, True, True, rules.WRITE_OWN),  # `run` looks at the test's file first
        (0, False, True, True, False, rules.WRITE_PASSED),  # RUNNER: the flag wins
        (1, False, True, True, False, rules.WRITE_OWN),
        (77, True, False, False, False, rules.WRITE_SKIPPED),
        (0, False, False, False, False, rules.WRITE_NO_RESULT),
        (1, False, False, False, False, rules.WRITE_FAILED),
    ],
)
def test_what_the_result_file_holds(
    code: int, skip: bool, generate: bool, own: bool, shell: bool, written: str
) -> None:
    assert rules.what_to_write(code, skip, generate, own, shell) == written


def test_codes_once_the_result_is_decided() -> None:
    assert rules.code_for(rules.WRITE_NO_RESULT, 0) == rules.FAILED
    assert rules.code_for(rules.WRITE_OWN, 0, reports_failure=True) == rules.FAILED
    assert rules.code_for(rules.WRITE_OWN, 3, reports_failure=True) == 3  # its own code kept
    assert rules.code_for(rules.WRITE_PASSED, 0) == 0


def test_when_the_exit_becomes_a_case_of_its_own() -> None:
    assert rules.needs_exit_case(Outcome(-9, 1.0), 137, False, any_failed=True)
    assert rules.needs_exit_case(Outcome(1, 1.0), 1, False, any_failed=False)
    assert not rules.needs_exit_case(Outcome(1, 1.0), 1, False, any_failed=True)
    assert not rules.needs_exit_case(Outcome(77, 1.0), 77, True, any_failed=False)
    assert not rules.needs_exit_case(Outcome(0, 1.0), 0, False, any_failed=False)


def test_a_lost_output_file_or_result_file_fails_only_a_passing_run() -> None:
    assert rules.output_lost(0, "disk full")
    assert not rules.output_lost(0, None)
    assert not rules.output_lost(5, "disk full")
    assert rules.final(0, None, "disk full") == rules.FAILED
    assert rules.final(0, "cannot write", None) == rules.FAILED
    assert rules.final(5, "cannot write", "disk full") == 5
    assert rules.final(0, None, None) == 0
