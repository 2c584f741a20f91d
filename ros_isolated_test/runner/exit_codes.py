"""Exit codes of the runner, one meaning each, so CI logs and scripts can tell them apart."""

from __future__ import annotations

import signal

from ros_isolated_test import not_run

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from ros_isolated_test.process.supervisor import Outcome

PASSED = 0
#: The test failed: non-zero exit, failures in its result file, or no result file.
FAILED = 1
#: Nothing was run: bad arguments or settings, a preset ROS_DOMAIN_ID refused, or a result
#: or output path that cannot be used.
USAGE = 2
#: Nothing was run: no domain ID could be reserved (pool exhausted, lock dir unusable).
NO_DOMAIN = 3
#: Not run: the test is another share's of a split (``ROS_ISOLATED_TEST_SHARD``), when
#: it has no skip code of its own. Automake's and ctest's convention for "skipped": the
#: CMake include and macros set ctest's SKIP_RETURN_CODE to it.
NOT_HERE = 77
#: The runner's own ``--timeout`` ended the test (the convention of timeout(1)).
TIMEOUT = 124
#: The command exists but could not be executed (shell convention).
NOT_EXECUTABLE = 126
#: The command was not found (shell convention).
NOT_FOUND = 127


#: The pytest plugin's, for the same reasons: pytest's usage error, and sysexits.h's
#: EX_TEMPFAIL for a busy machine (the runner's 3 would read as pytest's internal error).
PLUGIN_USAGE = 4
PLUGIN_BUSY = 75


def for_not_run(error: not_run.NotRun) -> int:
    """The runner's exit code for a test that was not run: :data:`USAGE` or :data:`NO_DOMAIN`."""
    return NO_DOMAIN if error.reason == not_run.BUSY else USAGE


def plugin_code(error: not_run.NotRun) -> int:
    """The pytest plugin's exit code for the same: :data:`PLUGIN_USAGE` or :data:`PLUGIN_BUSY`."""
    return PLUGIN_BUSY if error.reason == not_run.BUSY else PLUGIN_USAGE


def for_signal(signum: int) -> int:
    """Exit code of a process killed by ``signum``, as shells report it."""
    return 128 + signum


def signal_name(signum: int) -> str:
    """``SIGSEGV`` for 11; a number we cannot name stays a number."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


# --- the rules: how a test's end becomes an exit code and a result ----------------------------
#
# Pure decisions over plain values, so session only orchestrates and every rule can be
# read (and tested) in one place.

#: What the runner writes as the result file once the test has ended.
WRITE_PASSED = "passed"  # one passed case (--generate-result-on-success, `run`)
WRITE_SKIPPED = "skipped"  # --skip-return-code matched and the test wrote nothing
WRITE_NO_RESULT = "no result"  # exit 0 but no result file, in RUNNER mode: an error
WRITE_FAILED = "failed"  # the test failed and wrote nothing: its exit and output tail
WRITE_OWN = "own"  # the test's own file, made canonical


def ended(outcome: Outcome, ament: bool, timeout: float | None) -> tuple[int, str]:
    """The exit code for how the test ended, and the words saying how.

    ``ament``: run_test.py's contract, where a command that cannot start is code 1
    rather than the shell's 126/127.
    """
    if outcome.start_error is not None:
        error = outcome.start_error
        if ament:
            code = FAILED
        elif isinstance(error, FileNotFoundError):
            code = NOT_FOUND
        else:
            code = NOT_EXECUTABLE
        return code, f"could not be started: {error}"
    if outcome.received_signal is not None:
        received = signal_name(outcome.received_signal)
        how = (
            f"was killed by {signal_name(outcome.signal)}"
            if outcome.signal is not None
            else f"exited with code {outcome.returncode}"
        )
        return (
            for_signal(outcome.received_signal),
            f"was interrupted: the runner received {received}, passed it on, and the test {how}",
        )
    if outcome.timed_out:
        limit = f"{timeout:g}" if timeout is not None else "?"
        return (
            TIMEOUT,
            f"timed out after {outcome.duration:.1f} s (--timeout {limit}) and was stopped",
        )
    if outcome.signal is not None:
        name = signal_name(outcome.signal)
        return for_signal(outcome.signal), f"was killed by {name} (signal {outcome.signal})"
    assert outcome.returncode is not None
    return outcome.returncode, f"exited with code {outcome.returncode}"


def is_skip(outcome: Outcome, skip_return_code: int | None) -> bool:
    """Whether the test's return code is the one --skip-return-code names."""
    return skip_return_code is not None and outcome.returncode == skip_return_code


def what_to_write(
    code: int, skip: bool, generate_on_success: bool, own_file: bool, shell: bool
) -> str:
    """Which result file the runner leaves (one of the ``WRITE_*`` values).

    In RUNNER mode --generate-result-on-success wins over the test's own file, as in
    run_test.py; ``run`` always generates, so it must look at the test's own file first.
    """
    if code == PASSED and generate_on_success and not (shell and own_file):
        return WRITE_PASSED
    if own_file:
        return WRITE_OWN
    if skip:
        return WRITE_SKIPPED
    if code == PASSED:
        return WRITE_NO_RESULT
    return WRITE_FAILED


def code_for(written: str, code: int, reports_failure: bool = False) -> int:
    """The exit code once ``written`` is decided: a missing or failing result fails the run.

    ``reports_failure``: the result file written reports failures or errors.
    """
    if written == WRITE_NO_RESULT:
        return FAILED
    if reports_failure:
        return code or FAILED
    return code


def needs_exit_case(outcome: Outcome, code: int, skip: bool, any_failed: bool) -> bool:
    """Whether the test's own cases need one more, saying how its process ended.

    A death by signal, a timeout or an interruption always adds one; a non-zero exit
    adds one only when no case failed (the cases already explain it otherwise).
    """
    abnormal = (
        outcome.signal is not None or outcome.timed_out or outcome.received_signal is not None
    )
    return abnormal or (code != PASSED and not skip and not any_failed)


def output_lost(code: int, file_error: str | None) -> bool:
    """Whether a test that otherwise passed must fail: its --output-file lost output.

    The console got everything, but a log the user asked for is incomplete; a run
    that already failed keeps its own code.
    """
    return file_error is not None and code == PASSED


def final(code: int, result_write_error: str | None, file_error: str | None) -> int:
    """The runner's exit code: a result or output file that could not be written fails a pass."""
    if code == PASSED and (result_write_error is not None or file_error is not None):
        return FAILED
    return code
