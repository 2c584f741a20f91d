"""How the test ended, turned into its result file's final word and the runner's exit code.

The rules (which code, what to write) are pure functions in ``exit_codes``; this
module applies them: it gathers what the attempt left (its outcome, its own result
file, the output's tail) and has the result file write the word they decide.
"""

from __future__ import annotations

from ros_isolated_test import names
from ros_isolated_test.runner import exit_codes
from ros_isolated_test.runner.request import Mode
from ros_isolated_test.xunit.model import Case, Outcome
from ros_isolated_test.xunit.result_file import NO_RESULT

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from pathlib import Path

    from ros_isolated_test.process import supervisor
    from ros_isolated_test.process.capture import OutputCapture
    from ros_isolated_test.runner.request import RunRequest
    from ros_isolated_test.xunit.result_file import ResultFile


def conclude(
    request: RunRequest,
    result: ResultFile,
    capture: OutputCapture,
    outcome: supervisor.Outcome,
) -> int:
    """Turn how the test ended into the result file and the exit code (rules: exit_codes)."""
    code, reason = exit_codes.ended(outcome, request.mode is Mode.AMENT, request.timeout)
    result.properties[names.EXIT] = reason
    if outcome.returncode is not None and outcome.returncode >= 0:
        result.properties[names.EXIT_CODE] = str(outcome.returncode)
    if outcome.signal is not None:
        result.properties[names.SIGNAL] = exit_codes.signal_name(outcome.signal)
    result.properties[names.DURATION] = f"{outcome.duration:.3f}"
    if outcome.start_error is not None:
        capture.note(f"invocation failed: {outcome.start_error}")
    capture.note(f"the test {reason}")
    streams_noted(result, capture)
    if result.path is None:
        return code
    duration = outcome.duration
    skip = exit_codes.is_skip(outcome, request.skip_return_code)
    written = exit_codes.what_to_write(
        code,
        skip,
        request.generate_result_on_success,
        own_file=not result.untouched(),
        shell=request.mode is Mode.SHELL,
    )
    if written == exit_codes.WRITE_OWN:
        return _adopt(request, result, capture, outcome, code, reason, skip)
    # The tail only where it is shown: decoding it costs a passing test (locale, 64 KiB).
    if written == exit_codes.WRITE_PASSED:
        cases = [result.case(Outcome.PASSED, duration=duration)]
    elif written == exit_codes.WRITE_SKIPPED:
        capture.note(f"return code {outcome.returncode} means skipped (--skip-return-code)")
        message = f"Test skipped: it returned {outcome.returncode}."
        cases = [result.case(Outcome.SKIPPED, message, duration)]
    elif written == exit_codes.WRITE_NO_RESULT:
        cases = [result.case(Outcome.ERROR, f"{NO_RESULT}\n\n{capture.tail_text()}", duration)]
        capture.note(f"{NO_RESULT} Failing it (write one, or use --generate-result-on-success)")
    else:
        kind = Outcome.ERROR if outcome.start_error is not None else Outcome.FAILURE
        detail = f"The test {reason}."
        if request.mode is Mode.AMENT:
            detail = f"{NO_RESULT} {detail}"
        cases = [result.case(kind, f"{detail}\n\n{capture.tail_text()}", duration)]
    output = ""
    code = exit_codes.code_for(written, code)
    if exit_codes.output_lost(code, capture.file_error):
        cases.append(_output_lost_case(result, capture, request.output_file))
        output = capture.tail_text()
        code = exit_codes.FAILED  # a pass whose output file lost output fails
    result.write(cases, duration, output)
    return code


def _adopt(
    request: RunRequest,
    result: ResultFile,
    capture: OutputCapture,
    outcome: supervisor.Outcome,
    code: int,
    reason: str,
    skip: bool,
) -> int:
    """The test wrote its own result file: make it canonical, reconciled with its exit."""
    from ros_isolated_test.xunit import normalise

    cases = result.adopt()
    for problem in result.problems:
        capture.note(f"result file {result.path}: {problem}")
    any_failed = any(case.outcome.failed for case in cases)
    if exit_codes.needs_exit_case(outcome, code, skip, any_failed):
        cases.append(normalise.exit_case(result.suite_name, reason, all_passed=not any_failed))
        any_failed = True
    if not any_failed and exit_codes.output_lost(code, capture.file_error):
        cases.append(_output_lost_case(result, capture, request.output_file))
        any_failed = True
    output = capture.tail_text() if any_failed or code else ""
    rendered = result.write(cases, outcome.duration, output, checked=True)
    reports_failure = rendered is not None and rendered.failed
    if reports_failure:
        capture.note(f"the result file {result.path} reports failures or errors")
    return exit_codes.code_for(exit_codes.WRITE_OWN, code, reports_failure)


def streams_noted(result: ResultFile, capture: OutputCapture) -> None:
    """What went wrong with the output file (fails a pass) or the console (never does)."""
    if capture.file_error is not None:
        result.properties[names.OUTPUT_FILE_ERROR] = capture.file_error
    if capture.console_error is not None:
        result.properties[names.CONSOLE_ERROR] = capture.console_error


def _output_lost_case(result: ResultFile, capture: OutputCapture, output_file: Path | None) -> Case:
    """An error case for a test that passed but whose --output-file lost output (full disk)."""
    message = (
        f"{capture.file_error}; so --output-file {output_file} is incomplete "
        "(the console and this result file got the output); free space or choose another path"
    )
    return Case.saying(result.suite_name, "output file", Outcome.ERROR, message)
