"""The one orchestration path: reserve a domain, run the test, write its result, pick the code.

Every entry point (shell ``run``, ctest RUNNER script, Docker entrypoint) builds a
:class:`~ros_isolated_test.runner.request.RunRequest` and calls :func:`run`.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import sys
from collections.abc import Iterator
from pathlib import Path

from ros_isolated_test.domain_coordinator.lock_dir import LockDirError
from ros_isolated_test.domain_coordinator.pool import PoolSpecError
from ros_isolated_test.domain_coordinator.reservation import (
    DomainCoordinator,
    PoolExhaustedError,
)
from ros_isolated_test.process import supervisor
from ros_isolated_test.process.capture import OutputCapture
from ros_isolated_test.runner import environment, exit_codes
from ros_isolated_test.runner.discovery import DiscoveryError
from ros_isolated_test.runner.request import Mode, RunRequest
from ros_isolated_test.xunit.model import Outcome
from ros_isolated_test.xunit.result_file import NO_RESULT, ResultFile

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from types import FrameType
    from typing import BinaryIO


def run(request: RunRequest, console: BinaryIO | None = None) -> int:
    """Reserve, run, write results; return the exit code the caller should exit with."""
    console = console if console is not None else sys.stdout.buffer
    result = ResultFile(request)
    try:
        result.prepare()
    except OSError as error:
        message = (
            f"cannot use result file {request.result_file}: {error.strerror}; "
            "choose a writable file path"
        )
        _error(console, message)
        return exit_codes.USAGE
    try:
        output = _open_output(request.output_file)
    except OSError as error:
        message = (
            f"cannot open output file {request.output_file}: {error.strerror}; "
            "choose a writable file path"
        )
        return _not_run(result, console, message, Outcome.ERROR, exit_codes.USAGE)
    with output as handle:
        capture = OutputCapture(console, handle)
        code = _run(request, result, capture, console)
    # A result that could not be written is a failed run, never a silent pass.
    return exit_codes.FAILED if code == 0 and result.write_error else code


def _run(request: RunRequest, result: ResultFile, capture: OutputCapture, console: BinaryIO) -> int:
    if request.skip_test:
        capture.note("skipping the test (--skip-test)")
        result.write([result.case(Outcome.SKIPPED, "Test skipped by developer (SKIP_TEST)")])
        return exit_codes.PASSED
    try:
        policy = environment.decide(
            request.env, env_origin=request.env_origin, discovery_range=request.discovery_range
        )
    except environment.RefusedError as refusal:
        return _not_run(result, console, str(refusal), Outcome.FAILURE, exit_codes.USAGE)
    except DiscoveryError as error:
        return _not_run(result, console, str(error), Outcome.ERROR, exit_codes.USAGE)
    result.write_placeholder()
    guard = _Guard()
    try:
        with _interruptible(guard), _domain(policy, request, capture) as domain_id:
            if domain_id is not None:
                capture.line(f"Running with ROS_DOMAIN_ID {domain_id}")
                result.properties["ros_domain_id"] = str(domain_id)
                env = policy.for_domain(domain_id)
                if policy.discovery is not None:
                    capture.note(policy.discovery.describe())
                    for warning in policy.discovery.warnings:
                        capture.note(warning)
                    result.properties.update(policy.discovery.properties())
            else:
                result.properties["ros_domain_id"] = policy.env.get(
                    environment.DOMAIN_VAR, "unset (0)"
                )
                result.properties["isolation"] = "disabled"
                env = policy.env
            for note in policy.notes:
                capture.note(note)
            capture.note(f"invoking in '{os.getcwd()}': {shlex.join(request.command)}")
            guard.test_started = True
            outcome = supervisor.run(
                request.command, env, capture, request.timeout, request.kill_grace
            )
    except PoolSpecError as error:
        return _not_run(result, console, str(error), Outcome.ERROR, exit_codes.USAGE)
    except (PoolExhaustedError, LockDirError) as error:
        return _not_run(result, console, str(error), Outcome.ERROR, exit_codes.NO_DOMAIN)
    except Interrupted as interruption:
        name = exit_codes.signal_name(interruption.signum)
        message = f"interrupted by {name} before the test started (it never ran)"
        result.properties["signal_received"] = name
        return _not_run(
            result, console, message, Outcome.ERROR, exit_codes.for_signal(interruption.signum)
        )
    if guard.late is not None:
        # The test had ended: the run's outcome stands, the signal is only noted.
        result.properties["signal_after_test"] = exit_codes.signal_name(guard.late)
    for leftover in outcome.leftovers:
        capture.note(f"stopped process {leftover}, left running by the test")
    if outcome.leftovers:
        result.properties["leftover_processes"] = ", ".join(outcome.leftovers)
    return _conclude(request, result, capture, outcome)


class Interrupted(Exception):
    """A signal ended the run before the test started (while waiting for an ID)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


class _Guard:
    """Whether the test has started: a signal after that must not say it never ran."""

    def __init__(self) -> None:
        self.test_started = False
        self.late: int | None = None


@contextlib.contextmanager
def _interruptible(guard: _Guard) -> Iterator[None]:
    """Until the supervisor takes over, SIGINT/SIGTERM/SIGHUP end the run cleanly.

    Needed for a runner queued for an ID (and for PID 1, which has no default action).
    Once the test has run, a signal (while the ID is released) is only remembered.
    Outside the main thread (an embedding program) handlers cannot be set: the
    program's own stay.
    """

    def stop(signum: int, _frame: FrameType | None) -> None:
        if guard.test_started:
            guard.late = signum
            return
        raise Interrupted(signum)

    previous = supervisor.set_handlers(stop)
    try:
        yield
    finally:
        supervisor.restore_handlers(previous)


@contextlib.contextmanager
def _domain(
    policy: environment.Policy, request: RunRequest, capture: OutputCapture
) -> Iterator[int | None]:
    if not policy.isolate:
        yield None
        return
    coordinator = DomainCoordinator()
    with coordinator.reserve(request.command, request.wait_timeout, capture.note) as held:
        yield held.domain_id


def _conclude(
    request: RunRequest,
    result: ResultFile,
    capture: OutputCapture,
    outcome: supervisor.Outcome,
) -> int:
    """Turn how the test ended into the result file and the exit code."""
    code, reason = _code_and_reason(request, outcome)
    result.properties["exit"] = reason
    if outcome.returncode is not None and outcome.returncode >= 0:
        result.properties["exit_code"] = str(outcome.returncode)
    if outcome.signal is not None:
        result.properties["signal"] = exit_codes.signal_name(outcome.signal)
    result.properties["duration"] = f"{outcome.duration:.3f}"
    if outcome.start_error is not None:
        capture.note(f"invocation failed: {outcome.start_error}")
    capture.note(f"the test {reason}")
    if result.path is None:
        return code
    duration = outcome.duration
    skip_code = (
        request.skip_return_code is not None and outcome.returncode == request.skip_return_code
    )
    # ctest RUNNER: the flag wins over the test's own file, as in run_test.py. `run` never
    # throws away a file the test wrote itself: it always generates, so it must look first.
    own_file_first = request.mode is Mode.SHELL and not result.untouched()
    if code == 0 and request.generate_result_on_success and not own_file_first:
        result.write([result.case(Outcome.PASSED, duration=duration)], duration)
        return code
    if result.untouched():
        output = capture.tail_text()
        if skip_code:
            capture.note(f"return code {outcome.returncode} means skipped (--skip-return-code)")
            message = f"Test skipped: it returned {outcome.returncode}."
            result.write([result.case(Outcome.SKIPPED, message, duration)], duration)
            return code
        if code == 0:
            message = f"{NO_RESULT}\n\n{output}"
            result.write([result.case(Outcome.ERROR, message, duration)], duration)
            capture.note(f"{NO_RESULT} Failing it (write one, or use --generate-result-on-success)")
            return exit_codes.FAILED
        kind = Outcome.ERROR if outcome.start_error is not None else Outcome.FAILURE
        detail = f"The test {reason}."
        if request.mode is Mode.AMENT:
            detail = f"{NO_RESULT} {detail}"
        result.write([result.case(kind, f"{detail}\n\n{output}", duration)], duration)
        return code
    from ros_isolated_test.xunit import normalise

    cases = result.adopt()
    for problem in result.problems:
        capture.note(f"result file {result.path}: {problem}")
    abnormal = (
        outcome.signal is not None or outcome.timed_out or outcome.received_signal is not None
    )
    if abnormal or (code != 0 and not skip_code and not any(c.outcome.failed for c in cases)):
        cases.append(
            normalise.exit_case(
                result.suite_name, reason, all_passed=not any(c.outcome.failed for c in cases)
            )
        )
    failed = any(case.outcome.failed for case in cases)
    output = capture.tail_text() if failed or code else ""
    rendered = result.write(cases, duration, output, checked=True)
    if rendered is not None and rendered.failed:
        capture.note(f"the result file {result.path} reports failures or errors")
        return code or exit_codes.FAILED
    return code


def _code_and_reason(request: RunRequest, outcome: supervisor.Outcome) -> tuple[int, str]:
    if outcome.start_error is not None:
        error = outcome.start_error
        if request.mode is Mode.AMENT:
            return exit_codes.FAILED, f"could not be started: {error}"
        if isinstance(error, FileNotFoundError):
            return exit_codes.NOT_FOUND, f"could not be started: {error}"
        return exit_codes.NOT_EXECUTABLE, f"could not be started: {error}"
    if outcome.received_signal is not None:
        received = exit_codes.signal_name(outcome.received_signal)
        ended = (
            f"was killed by {exit_codes.signal_name(outcome.signal)}"
            if outcome.signal is not None
            else f"exited with code {outcome.returncode}"
        )
        return (
            exit_codes.for_signal(outcome.received_signal),
            f"was interrupted: the runner received {received}, passed it on, and the test {ended}",
        )
    if outcome.timed_out:
        limit = f"{request.timeout:g}" if request.timeout is not None else "?"
        return (
            exit_codes.TIMEOUT,
            f"timed out after {outcome.duration:.1f} s (--timeout {limit}) and was stopped",
        )
    signum = outcome.signal
    if signum is not None:
        name = exit_codes.signal_name(signum)
        return exit_codes.for_signal(signum), f"was killed by {name} (signal {signum})"
    assert outcome.returncode is not None
    return outcome.returncode, f"exited with code {outcome.returncode}"


def report_usage_error(message: str, result_file: Path | None) -> int:
    """Arguments that cannot be understood: say so in one line, still leave a result file."""
    result = ResultFile(RunRequest(command=(), mode=Mode.AMENT, result_file=result_file))
    try:
        result.prepare()
    except OSError:
        _error(sys.stdout.buffer, message)
        return exit_codes.USAGE
    return _not_run(result, sys.stdout.buffer, message, Outcome.ERROR, exit_codes.USAGE)


def _not_run(result: ResultFile, console: BinaryIO, message: str, kind: Outcome, code: int) -> int:
    # The result file first: after a Ctrl-C the console may already be gone.
    result.properties["exit"] = "not run"
    result.write([result.case(kind, message)])
    _error(console, message)
    return code


def _error(console: BinaryIO, message: str) -> None:
    """One line on stderr, where CI and humans look for errors; flushed after stdout."""
    with contextlib.suppress(OSError, ValueError):
        console.flush()
    with contextlib.suppress(OSError, ValueError):
        # A reader that went away (ctest killed by the same Ctrl-C) loses nothing here:
        # everything this says is in the result file already.
        print(f"ros-isolated-test: error: {message}", file=sys.stderr, flush=True)


def _open_output(path: Path | None) -> contextlib.AbstractContextManager[BinaryIO | None]:
    if path is None:
        return contextlib.nullcontext()
    path.parent.mkdir(parents=True, exist_ok=True)
    # Unbuffered: a failing write is seen (and survived) at once, never at close.
    return open(path, "wb", buffering=0)
