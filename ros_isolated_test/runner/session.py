"""The one orchestration path: reserve a domain, run the test, write its result, pick the code.

Every entry point (shell ``run``, ctest RUNNER script, Docker entrypoint) builds a
:class:`~ros_isolated_test.runner.request.RunRequest` and calls :func:`run`. Read it
as the table of contents of a run; each step lives in a module of its own:

0. ``shard``: in a split, a test of another share is not run at all (nothing reserved,
   no result file); this share's tests record it;
1. ``streams``: the console and the --output-file, or one line saying why not;
2. the result file (``xunit.result_file``): stale files gone, a placeholder in place;
3. ``environment``: the policy (refusing a preset ROS_DOMAIN_ID, for one);
4. ``interruption``: from here until the final word, a signal never loses the result;
5. ``attempt``: hold an ID (``isolation``), run the test, end its tree, release;
6. ``verdict``: how it ended becomes the final word and the exit code, or ``reruns``
   runs it again first;
7. with ``ROS_ISOLATED_TEST_HISTORY`` set, the final result file into the test history
   (``history.record``): a warning at worst, never another exit code.

The pytest plugin, whose tests run in its own process, shares step 5's holding
(:func:`~ros_isolated_test.runner.isolation.isolation`) and step 5's first lines
(``summary``).
"""

from __future__ import annotations

import contextlib

from ros_isolated_test import names
from ros_isolated_test.atomic_file import SPECIAL_FIX, NotReplaceableError
from ros_isolated_test.not_run import NotRun
from ros_isolated_test.runner import environment, exit_codes, settings, shard, streams
from ros_isolated_test.runner.attempt import attempt
from ros_isolated_test.runner.interruption import Guard, Interrupted, interruptible
from ros_isolated_test.runner.request import Mode, RunRequest
from ros_isolated_test.runner.summary import NOTES_SEPARATOR, SETTINGS_NOTES
from ros_isolated_test.runner.verdict import conclude, streams_noted
from ros_isolated_test.xunit.model import Outcome
from ros_isolated_test.xunit.result_file import ResultFile

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from pathlib import Path
    from typing import BinaryIO


def run(request: RunRequest, console: BinaryIO | None = None) -> int:
    """Reserve, run, write results; return the exit code the caller should exit with."""
    streams.keep_standard_descriptors()
    console = console if console is not None else streams.console()
    result = _result_file(request)
    elsewhere = shard.decide(request, result, console)
    if elsewhere is not None:
        return elsewhere
    try:
        result.prepare()
    except OSError as error:
        # Nothing reserved, nothing started, and no result file: its path is what is wrong.
        fix = "choose a writable file path"
        if isinstance(error, NotReplaceableError):
            fix = SPECIAL_FIX
        streams.error(
            console, f"cannot use result file {request.result_file}: {error.strerror}; {fix}"
        )
        return exit_codes.USAGE
    # result.path: None when the result is discarded (/dev/null), which clashes with nothing.
    clash = streams.same_file_message(request.output_file, result.path)
    if clash is not None:
        return _not_run(result, console, clash, Outcome.ERROR, exit_codes.USAGE)
    if not result.write_placeholder():
        # Said on stderr already. Nothing may run: if ctest killed the runner now, no
        # file would say what happened, and the final write would most likely fail too.
        return exit_codes.USAGE
    # After the placeholder: opening a FIFO or a device can fail (or, blocking, hang).
    try:
        output = streams.open_output(request.output_file)
    except OSError as error:
        message = streams.output_message(request.output_file, error)
        return _not_run(result, console, message, Outcome.ERROR, exit_codes.USAGE)
    with output as handle:
        both = streams.Streams(console, handle)
        try:
            code = _decided(request, result, both, console)
        finally:
            both.close()
    # A result or output file that could not be written is a failed run, never a silent pass.
    code = exit_codes.final(code, result.write_error, both.capture.file_error)
    _recorded(request, result)
    return shard.exit_code(request, code, console)


def _recorded(request: RunRequest, result: ResultFile) -> None:
    """Step 7: ``run``'s result file, final now, into the history the variable names, if any.

    ``run`` alone: a test run by ctest is one of a run of many, which one recorder takes
    whole (the colcon extension, or ``history record`` over the build), never test by test.
    """
    if request.mode is not Mode.SHELL:
        return
    db = settings.history_to_record()
    if db is None or result.path is None or result.write_error:
        return
    # Only when asked: sqlite3 and the report's reading are not on a test's path otherwise.
    from ros_isolated_test.history.record import record_trees

    warning = record_trees(db, [result.path])
    if warning is not None:
        import sys

        with contextlib.suppress(OSError, ValueError):
            print(warning, file=sys.stderr, flush=True)


def _decided(
    request: RunRequest, result: ResultFile, both: streams.Streams, console: BinaryIO
) -> int:
    """Skip the test, refuse it (a preset ID, say), or run it under the policy decided."""
    capture = both.capture
    if request.skip_test:
        capture.note("skipping the test (--skip-test)")
        streams_noted(result, capture)
        result.write([result.case(Outcome.SKIPPED, "Test skipped by developer (SKIP_TEST)")])
        return exit_codes.PASSED
    try:
        policy = environment.decide(
            request.env,
            request.settings,
            env_origin=request.env_origin,
            command=request.command,
            result_file=request.result_file,
        )
    except NotRun as error:  # a preset ID refused, a discovery that cannot be had
        return _never_ran(result, console, error)
    guard = Guard()
    # The handlers stay until the final word is written: a signal after the test ended
    # (ctest's SIGTERM, a Ctrl-C) is noted in the result, never lets the result be lost.
    with interruptible(guard):
        return _attempted(request, policy, result, both, console, guard)


def _attempted(
    request: RunRequest,
    policy: environment.Policy,
    result: ResultFile,
    both: streams.Streams,
    console: BinaryIO,
    guard: Guard,
) -> int:
    """The first attempt, then its verdict (or the reruns'): the run's final word."""
    config = request.settings
    if policy.isolate and config.notes:
        # Recorded before the reservation: a run that gets no ID says it too.
        result.properties[SETTINGS_NOTES] = NOTES_SEPARATOR.join(config.notes)
    if config.reruns:
        result.properties[names.RERUN_FAILURES] = str(config.reruns)
    # What every attempt's result starts from (an attempt adds its ID, its exit, ...).
    base = dict(result.properties)
    try:
        outcome, domain_id = attempt(request, 1, policy, config, result, both.capture, guard)
    except NotRun as error:  # no ID came free, capacities disagree, namespaces refused
        return _never_ran(result, console, error)
    except Interrupted as interruption:
        name = exit_codes.signal_name(interruption.signum)
        message = f"interrupted by {name} before the test started (it never ran)"
        result.properties[names.SIGNAL_RECEIVED] = name
        return _not_run(
            result, console, message, Outcome.ERROR, exit_codes.for_signal(interruption.signum)
        )
    guard.result = result
    guard.note_late()  # one that came while the ID was released
    if config.reruns or config.reruns_flaky:  # reruns_flaky: where the history says flaky
        from ros_isolated_test.runner.reruns import reruns  # a test that has none loads none

        code = reruns(request, policy, config, result, both, guard, base, outcome, domain_id)
    else:
        code = conclude(request, result, both.capture, outcome)
    if guard.late is not None and names.SIGNAL_AFTER_TEST not in result.written:
        # It came while the final word was being written: written again, saying so.
        result.rewrite()
    return code


def report_usage_error(message: str, result_file: Path | None) -> int:
    """Arguments that cannot be understood: say so in one line, still leave a result file."""
    streams.keep_standard_descriptors()
    # Never run: built-in settings, so a usage error never reads (nor trips on) a variable.
    request = RunRequest((), Mode.AMENT, settings.defaults(), result_file=result_file)
    result = _result_file(request)
    try:
        result.prepare()
    except OSError:
        streams.error(streams.console(), message)
        return exit_codes.USAGE
    return _not_run(result, streams.console(), message, Outcome.ERROR, exit_codes.USAGE)


def _result_file(request: RunRequest) -> ResultFile:
    """The request's result file, its suite named as ament names the test."""
    return ResultFile(request.result_file, request.command, request.package, request.test_name)


def _never_ran(result: ResultFile, console: BinaryIO, error: NotRun) -> int:
    """The test was not run: the outcome and exit code its error carries (``exit_codes``)."""
    return _not_run(
        result, console, str(error), Outcome(error.outcome), exit_codes.for_not_run(error)
    )


def _not_run(result: ResultFile, console: BinaryIO, message: str, kind: Outcome, code: int) -> int:
    # The result file first: after a Ctrl-C the console may already be gone.
    result.properties[names.EXIT] = "not run"
    result.write([result.case(kind, message)])
    streams.error(console, message)
    return code
