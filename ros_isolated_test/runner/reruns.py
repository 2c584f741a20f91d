"""Running a failed test again (--rerun-failures N): when, on which ID, and what is kept.

Each attempt after the previous one's full cleanup (tree swept, ID released), on an ID
reserved afresh; each attempt's result is made canonical before the next one can
overwrite the test's own file. The file left holds every attempt (``write_attempts``);
the exit code is the last attempt's. A signal, a rerun that gets no ID, or a failure
no rerun can change (the command cannot start, the result cannot be written) ends
the series.
"""

from __future__ import annotations

from ros_isolated_test import names
from ros_isolated_test.not_run import NotRun
from ros_isolated_test.runner import environment, exit_codes
from ros_isolated_test.runner.attempt import attempt
from ros_isolated_test.runner.interruption import Interrupted
from ros_isolated_test.runner.verdict import conclude

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from ros_isolated_test.process import supervisor
    from ros_isolated_test.process.capture import OutputCapture
    from ros_isolated_test.runner import settings
    from ros_isolated_test.runner.interruption import Guard
    from ros_isolated_test.runner.request import RunRequest
    from ros_isolated_test.runner.streams import Streams
    from ros_isolated_test.xunit.result_file import ResultFile


def flaky_by_history(request: RunRequest) -> str | None:
    """The line to say when the test history calls this test flaky; None when it does not.

    The test is named as the history names it (``<package>/<test>``); the database is
    ROS_ISOLATED_TEST_HISTORY, else ``history``'s default in the current folder. Read
    only now, after a failure: sqlite3 is never imported for a test that passes.
    """
    from pathlib import Path

    from ros_isolated_test.history.stats import called_flaky
    from ros_isolated_test.history.store import DEFAULT_FILE
    from ros_isolated_test.runner.settings import RERUNS_FLAKY_ENV, history_database
    from ros_isolated_test.shard.identity import IdentityError, identity

    try:
        name = identity(request.package, request.test_name)
    except IdentityError:
        return None
    db = history_database() or Path(DEFAULT_FILE)
    if not called_flaky(db, name):
        return None
    reruns = request.settings.reruns_flaky
    return (
        f"the test history calls {name} flaky: running it again up to {reruns} time(s) "
        f"({RERUNS_FLAKY_ENV})"
    )


def reruns(
    request: RunRequest,
    policy: environment.Policy,
    config: settings.Settings,
    result: ResultFile,
    streams: Streams,
    guard: Guard,
    base: dict[str, str],
    outcome: supervisor.Outcome,
    domain_id: int | None,
) -> int:
    """Conclude the first attempt; while it failed and reruns are left, run the test again.

    ``base`` holds the properties every attempt's result starts from; ``outcome`` and
    ``domain_id`` are the first attempt's.
    """
    from ros_isolated_test.xunit.attempts import ATTEMPTS_PROPERTY

    total = config.reruns + 1
    # Reruns where needed: more of them only for a test the history calls flaky, asked
    # once, at the first failure that the plain reruns would not run again.
    ask_history = config.reruns_flaky > config.reruns
    ids: list[str] = []
    number = ran = 1
    # What a test that passes at once says: one attempt, no rewrite needed.
    result.properties[ATTEMPTS_PROPERTY] = "1"
    while True:
        capture = streams.capture
        code = conclude(request, result, capture, outcome)
        result.end_attempt()
        ids.append("unset" if domain_id is None else str(domain_id))
        ran = number
        why = _failed_because(outcome, code, capture, result)
        if why is not None and number == total and ask_history and guard.late is None:
            ask_history = False
            said = flaky_by_history(request)
            if said is not None:
                total = config.reruns_flaky + 1
                capture.note(said)
                base[names.RERUN_FLAKY] = str(config.reruns_flaky)  # every attempt's
                result.properties[names.RERUN_FLAKY] = base[names.RERUN_FLAKY]
        if why is None or number == total or guard.late is not None:
            break
        number += 1
        capture.note(f"attempt {number} of {total}: attempt {number - 1} failed ({why})")
        capture = streams.next_attempt()
        if not result.next_attempt(number - 1, base):
            break  # said on stderr; the attempts so far are written below
        try:
            # Signals end a rerun that has not started yet (one queued for an ID) at once.
            guard.next_attempt()
            outcome, domain_id = attempt(request, number, policy, config, result, capture, guard)
        except NotRun as error:
            capture.note(f"attempt {number} did not run: {error}")
            result.properties[names.RERUN_NOT_RUN] = str(error)
            break
        except Interrupted as interruption:
            name = exit_codes.signal_name(interruption.signum)
            capture.note(f"attempt {number} did not run: interrupted by {name}")
            result.properties[names.SIGNAL_AFTER_TEST] = name
            break
    if result.attempts_written < 2 or result.path is None:
        if number > ran:
            # A rerun that never started: the last attempt's word, with why it stopped.
            result.properties = {**base, **result.written, **result.properties}
            result.rewrite()
        return code
    rendered = result.write_attempts(ids)
    if rendered is not None and rendered.failed and code == exit_codes.PASSED:
        code = exit_codes.FAILED  # a merged file that fails (a bug of ours) never passes
    return code


def _failed_because(
    outcome: supervisor.Outcome, code: int, capture: OutputCapture, result: ResultFile
) -> str | None:
    """Why this attempt failed in a way a rerun may change; None: it passed, or no rerun can."""
    if code == exit_codes.PASSED or outcome.start_error is not None:
        return None
    if outcome.received_signal is not None or result.write_error is not None:
        return None  # the runner was told to stop / the result cannot be written
    if capture.file_error is not None:
        return None  # the output file is cut short whatever a rerun does
    if outcome.timed_out:
        return "timed out"
    if outcome.signal is not None:
        return f"killed by {exit_codes.signal_name(outcome.signal)}"
    if outcome.returncode:
        return f"exit code {outcome.returncode}"
    return "its result file reports failures"
