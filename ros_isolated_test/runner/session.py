"""The one orchestration path: reserve a domain, run the test, write its result, pick the code.

Every entry point (shell ``run``, ctest RUNNER script, Docker entrypoint) builds a
:class:`~ros_isolated_test.runner.request.RunRequest` and calls :func:`run`, which also
runs a failed test again when reruns are asked for (one loop for every entry point). The pytest
plugin, whose tests run in its own process, shares the part around the work: the
reservation, the end of what the work left behind, the blocks, the release
(:func:`isolation`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import shlex
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from ros_isolated_test.atomic_file import SPECIAL_FIX, NotReplaceableError
from ros_isolated_test.domain_coordinator.holdings import CapacityConflictError
from ros_isolated_test.domain_coordinator.lock_dir import LockDirError
from ros_isolated_test.domain_coordinator.pool import id_ranges
from ros_isolated_test.domain_coordinator.reservation import (
    DomainCoordinator,
    PoolExhaustedError,
    Reservation,
    ResourceHold,
)
from ros_isolated_test.process import reaper, supervisor
from ros_isolated_test.process.capture import OutputCapture
from ros_isolated_test.runner import environment, exit_codes, partition, settings
from ros_isolated_test.runner.discovery import DiscoveryError
from ros_isolated_test.runner.request import Mode, RunRequest
from ros_isolated_test.xunit.model import Case, Outcome
from ros_isolated_test.xunit.result_file import NO_RESULT, ResultFile, timeline_properties

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from types import FrameType
    from typing import BinaryIO

    from ros_isolated_test.process import proc
    from ros_isolated_test.xunit.model import Suite


def _result_file(request: RunRequest) -> ResultFile:
    """The request's result file, its suite named as ament names the test."""
    return ResultFile(request.result_file, request.command, request.package, request.test_name)


def run(request: RunRequest, console: BinaryIO | None = None) -> int:
    """Reserve, run, write results; return the exit code the caller should exit with."""
    _keep_standard_descriptors()
    console = console if console is not None else _console()
    result = _result_file(request)
    try:
        result.prepare()
    except OSError as error:
        # Nothing reserved, nothing started, and no result file: its path is what is wrong.
        fix = "choose a writable file path"
        if isinstance(error, NotReplaceableError):
            fix = SPECIAL_FIX
        _error(console, f"cannot use result file {request.result_file}: {error.strerror}; {fix}")
        return exit_codes.USAGE
    # result.path: None when the result is discarded (/dev/null), which clashes with nothing.
    clash = same_file_message(request.output_file, result.path)
    if clash is not None:
        return _not_run(result, console, clash, Outcome.ERROR, exit_codes.USAGE)
    if not result.write_placeholder():
        # Said on stderr already. Nothing may run: if ctest killed the runner now, no
        # file would say what happened, and the final write would most likely fail too.
        return exit_codes.USAGE
    # After the placeholder: opening a FIFO or a device can fail (or, blocking, hang).
    try:
        output = _open_output(request.output_file)
    except OSError as error:
        return _not_run(
            result,
            console,
            _output_message(request.output_file, error),
            Outcome.ERROR,
            exit_codes.USAGE,
        )
    with output as handle:
        streams = _Streams(console, handle)
        try:
            code = _run(request, request.settings, result, streams, console)
        finally:
            streams.close()
    # A result or output file that could not be written is a failed run, never a silent pass.
    return exit_codes.final(code, result.write_error, streams.capture.file_error)


def same_file_message(output_file: Path | None, result_file: Path | None) -> str | None:
    """The one-line error when --output-file and the result file are one file, else None.

    Compared resolved (``./x`` and ``x``, a symlink and its target): the output would
    overwrite the result, or the result replace the output, and one of them is lost.
    """
    if output_file is None or result_file is None:
        return None
    if os.path.realpath(output_file) != os.path.realpath(result_file):
        return None
    return (
        f"--output-file {output_file} is the result file {result_file}: one would overwrite "
        "the other; give the output file another name"
    )


def _keep_standard_descriptors() -> None:
    """Put /dev/null where stdin, stdout or stderr is closed (``>&-``).

    Otherwise the next file opened (a lock, the result file) takes descriptor 1 or 2:
    the test would inherit it as its stdout, and our own messages would land in it.
    """
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)  # the lowest free descriptor: ``fd``
            if null != fd:
                os.dup2(null, fd)
                os.close(null)


def _console() -> BinaryIO:
    """Where the test's output goes: stdout unbuffered, or nowhere when closed at start.

    Every chunk is written and flushed once anyway; a buffer would only keep bytes a
    failing console refused (a full device), and the interpreter's exit, flushing them
    again, would fail the run (code 120) although a console never fails it.
    """
    if sys.stdout is None:
        # Python leaves sys.stdout None for a descriptor closed at start: fd 1 is /dev/null.
        return open(1, "wb", buffering=0, closefd=False)  # lives as long as the run
    with contextlib.suppress(OSError, ValueError):
        sys.stdout.flush()  # what was printed before comes first
    stream: BinaryIO = getattr(sys.stdout.buffer, "raw", sys.stdout.buffer)
    return stream


class _Streams:
    """The console and --output-file every attempt writes to, and the current attempt's capture.

    Each attempt gets a capture of its own, so its result holds its own output tail; a
    console or output file that failed in an earlier attempt stays failed (and said so).
    """

    def __init__(self, console: BinaryIO, output: BinaryIO | None) -> None:
        self._console = console
        self._output = output
        self._null: BinaryIO | None = None
        self.capture = OutputCapture(console, output)

    def next_attempt(self) -> OutputCapture:
        """A fresh capture for the next attempt, after the same streams."""
        done = self.capture
        console = self._console
        if done.console_error is not None:
            # A stalled console would stall every attempt again: it gets nothing more.
            if self._null is None:
                self._null = open(os.devnull, "wb", buffering=0)  # noqa: SIM115 (closed in close)
            console = self._null
        output = self._output if done.file_error is None else None
        self.capture = OutputCapture(console, output)
        self.capture.console_error = done.console_error
        self.capture.file_error = done.file_error
        return self.capture

    def close(self) -> None:
        if self._null is not None:
            self._null.close()


def _run(
    request: RunRequest,
    config: settings.Settings,
    result: ResultFile,
    streams: _Streams,
    console: BinaryIO,
) -> int:
    capture = streams.capture
    if request.skip_test:
        capture.note("skipping the test (--skip-test)")
        _streams_noted(result, capture)
        result.write([result.case(Outcome.SKIPPED, "Test skipped by developer (SKIP_TEST)")])
        return exit_codes.PASSED
    try:
        policy = environment.decide(request.env, config, env_origin=request.env_origin)
    except environment.RefusedError as refusal:
        return _not_run(result, console, str(refusal), Outcome.FAILURE, exit_codes.USAGE)
    except DiscoveryError as error:
        return _not_run(result, console, str(error), Outcome.ERROR, exit_codes.USAGE)
    guard = _Guard()
    # The handlers stay until the final word is written: a signal after the test ended
    # (ctest's SIGTERM, a Ctrl-C) is noted in the result, never lets the result be lost.
    with _interruptible(guard):
        return _guarded(request, policy, config, result, streams, console, guard)


def _guarded(
    request: RunRequest,
    policy: environment.Policy,
    config: settings.Settings,
    result: ResultFile,
    streams: _Streams,
    console: BinaryIO,
    guard: _Guard,
) -> int:
    capture = streams.capture
    if policy.isolate and config.notes:
        # Recorded before the reservation: a run that gets no ID says it too.
        result.properties[SETTINGS_NOTES] = NOTES_SEPARATOR.join(config.notes)
    if config.reruns:
        result.properties[RERUNS_PROPERTY] = str(config.reruns)
    # What every attempt's result starts from (an attempt adds its ID, its exit, ...).
    base = dict(result.properties)
    command = _command_of(request, config, result, 1)
    try:
        outcome, domain_id = _attempt(request, command, policy, config, result, capture, guard)
    except (PoolExhaustedError, LockDirError) as error:
        return _not_run(result, console, str(error), Outcome.ERROR, exit_codes.NO_DOMAIN)
    except CapacityConflictError as error:
        return _not_run(result, console, str(error), Outcome.ERROR, exit_codes.USAGE)
    except environment.RefusedError as refusal:  # namespaces that cannot be had
        return _not_run(result, console, str(refusal), Outcome.FAILURE, exit_codes.USAGE)
    except Interrupted as interruption:
        name = exit_codes.signal_name(interruption.signum)
        message = f"interrupted by {name} before the test started (it never ran)"
        result.properties["signal_received"] = name
        return _not_run(
            result, console, message, Outcome.ERROR, exit_codes.for_signal(interruption.signum)
        )
    guard.result = result
    guard.note_late()  # one that came while the ID was released
    if config.reruns:
        code = _reruns(request, policy, config, result, streams, guard, base, outcome, domain_id)
    else:
        code = _conclude(request, result, capture, outcome)
    if guard.late is not None and "signal_after_test" not in result.written:
        # It came while the final word was being written: written again, saying so.
        result.rewrite()
    return code


def _command_of(
    request: RunRequest, config: settings.Settings, result: ResultFile, number: int
) -> tuple[str, ...]:
    """The command attempt ``number`` runs: in a rerun series, its own result file goes beside.

    The result path it names is pointed at ``result.own_file``, so the result path holds
    the record so far (earlier failures, this attempt not finished) until the runner
    merges the attempt in: a kill at any moment leaves a failing file.
    """
    if not config.reruns:
        return request.command
    own = result.own_file(number)
    return request.command if own is None else request.command_writing_to(own)


def _attempt(
    request: RunRequest,
    command: tuple[str, ...],
    policy: environment.Policy,
    config: settings.Settings,
    result: ResultFile,
    capture: OutputCapture,
    guard: _Guard,
) -> tuple[supervisor.Outcome, int | None]:
    """Run the test once on an ID of its own: reserve, run, end its tree, release.

    Returns how the test ended and the ID it ran on (None: isolation disabled). Raises
    PoolExhaustedError or LockDirError (no ID), or Interrupted (a signal before it started).
    """
    with isolation(policy, config, command, capture.note) as held:
        domain_id = None if held is None else held.domain_id
        reserved = held is None or held.reserved
        if domain_id is not None:
            capture.line(header_line(policy, domain_id, reserved))
        lines, properties = summary(policy, domain_id, config, reserved)
        if held is not None and held.resources:
            line, more = resources_summary(held, config)
            lines.insert(0, line)
            properties.update(more)
        for line in lines:
            capture.note(line)
        result.properties.update(properties)
        env = policy.env if domain_id is None else policy.for_domain(domain_id)
        capture.note(f"invoking in '{os.getcwd()}': {shlex.join(command)}")
        started = time.time()
        outcome = supervisor.run(
            command,
            env,
            capture,
            request.timeout,
            request.kill_grace,
            on_start=guard.start,
            namespaces=policy.namespaces,
        )
        if policy.namespaces and _namespaces_refused(outcome):
            # The test never ran: its start found namespaces forbidden (no probe before).
            assert outcome.start_error is not None
            raise policy.refusal(outcome.start_error)
        # When it ran, what it waited for first and on which pool: the report's timeline.
        waits = (0.0, 0.0) if held is None else (held.waited, held.waited_resources)
        pool = id_ranges(config.pool) if domain_id is not None else ""
        result.properties.update(timeline_properties(started, time.time(), *waits, pool))
        if held is not None:
            held.survivors = outcome.survivors  # what blocks the ID: as named below
        # Named before the ID is released: the block note (isolation) follows.
        for leftover in outcome.leftovers:
            capture.note(leftover_note(leftover))
        if outcome.leftovers:
            result.properties["leftover_processes"] = ", ".join(outcome.leftovers)
        survivors = [survivor.describe() for survivor in outcome.survivors]
        for survivor in survivors:
            capture.note(f"process {survivor} of the test could not be ended (SIGKILL failed)")
        if survivors:
            result.properties["surviving_processes"] = ", ".join(survivors)
    return outcome, domain_id


def _namespaces_refused(outcome: supervisor.Outcome) -> bool:
    """Whether the test could not start because its namespaces could not be made."""
    from ros_isolated_test.process.namespace import NamespaceError

    return isinstance(outcome.start_error, NamespaceError)


#: The suite property saying how many reruns a failed test was allowed.
RERUNS_PROPERTY = "rerun_failures"


def _reruns(
    request: RunRequest,
    policy: environment.Policy,
    config: settings.Settings,
    result: ResultFile,
    streams: _Streams,
    guard: _Guard,
    base: dict[str, str],
    outcome: supervisor.Outcome,
    domain_id: int | None,
) -> int:
    """Conclude the first attempt; while it failed and reruns are left, run the test again.

    Each attempt after the previous one's full cleanup (tree swept, ID released), on an
    ID reserved afresh; each attempt's result is made canonical before the next one can
    overwrite the test's own file. The file left holds every attempt (merge_attempts);
    the exit code is the last attempt's. A signal, a rerun that gets no ID, or a failure
    no rerun can change (the command cannot start, the result cannot be written) ends
    the series.
    """
    from ros_isolated_test.xunit.attempts import ATTEMPTS_PROPERTY, merge_attempts

    total = config.reruns + 1
    suites: list[Suite] = []
    ids: list[str] = []
    number = ran = 1
    while True:
        capture = streams.capture
        if number == 1:
            # What a test that passes at once says: one attempt, no rewrite needed.
            result.properties[ATTEMPTS_PROPERTY] = "1"
        result.last_suite = None  # set again only if this attempt's result is written
        code = _conclude(request, result, capture, outcome)
        ids.append("unset" if domain_id is None else str(domain_id))
        ran = number
        if result.last_suite is not None:
            suites.append(result.last_suite)
            # The merge counts the attempts itself; attempt 1's own count would be kept
            # as a difference (attempt_1.attempts).
            result.last_suite.properties.pop(ATTEMPTS_PROPERTY, None)
        why = _failed_because(outcome, code, capture, result)
        if why is None or number == total or guard.late is not None:
            break
        number += 1
        capture.note(f"attempt {number} of {total}: attempt {number - 1} failed ({why})")
        capture = streams.next_attempt()
        if not result.next_attempt(number - 1, base, _placeholder_merge(suites)):
            break  # said on stderr; the attempts so far are written below
        try:
            # Signals end a rerun that has not started yet (one queued for an ID) at once.
            guard.test_started = guard.concluding = False
            if guard.late is not None:
                raise Interrupted(guard.late)
            command = _command_of(request, config, result, number)
            outcome, domain_id = _attempt(request, command, policy, config, result, capture, guard)
        except (
            PoolExhaustedError,
            LockDirError,
            CapacityConflictError,
            environment.RefusedError,
        ) as error:
            capture.note(f"attempt {number} did not run: {error}")
            result.properties["rerun_not_run"] = str(error)
            break
        except Interrupted as interruption:
            name = exit_codes.signal_name(interruption.signum)
            capture.note(f"attempt {number} did not run: interrupted by {name}")
            result.properties["signal_after_test"] = name
            break
    if len(suites) < 2 or result.path is None:
        if number > ran:
            # A rerun that never started: the last attempt's word, with why it stopped.
            result.properties = {**base, **result.written, **result.properties}
            result.rewrite()
        return code
    merged = merge_attempts(suites)
    merged.properties["ros_domain_ids"] = ", ".join(ids)
    rendered = result.write_merged(merged)
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


def _placeholder_merge(suites: list[Suite]) -> Callable[[Suite], Suite]:
    """The attempts so far, then the one given: how a rerun's placeholder and result are written.

    The file on disk never shows a rerun without the earlier attempts: if ctest kills
    the runner during the rerun or as it writes the result, the failures before stay on
    record. No copies: merge_attempts builds new cases and never changes the suites it is given.
    """
    from ros_isolated_test.xunit.attempts import merge_attempts

    earlier = tuple(suites)  # those finished now; later ones are appended to ``suites``

    def merge(latest: Suite) -> Suite:
        return merge_attempts([*earlier, latest])

    return merge


def header_line(policy: environment.Policy, domain_id: int, reserved: bool = True) -> str:
    """The runner's first line: the test's domain ID, and its Gazebo partition beside it.

    Starts as upstream's does (``Running with ROS_DOMAIN_ID <id>``): what greps for it
    finds it. Then, where isolation is not the default, what keeps the test apart:
    its namespaces (and whether the ID is its own), or auto's fall-back to the ID alone.
    """
    gz_name = policy.partition_for(domain_id)
    line = f"Running with ROS_DOMAIN_ID {domain_id}"
    if gz_name is not None:
        line += f" (Gazebo partition {gz_name})"
    if policy.namespaces and reserved:
        line += ", in namespaces of its own"
    elif policy.namespaces:
        line += (
            f", in namespaces of its own; ID {domain_id} is not reserved (no ID of the pool "
            "is free): the namespaces isolate the test"
        )
    elif policy.fallback is not None:
        line += "; isolation auto: by the domain ID alone, no namespaces (see below)"
    return line


def resources_summary(held: Held, config: settings.Settings) -> tuple[str, dict[str, str]]:
    """The line saying what the test holds besides its ID, and the properties recording it."""
    from ros_isolated_test.domain_coordinator.resources import describe

    asked = describe(held.resources)
    capacity = describe({name: config.capacity[name] for name in held.resources})
    line = f"holding {asked} of {capacity} (waited {held.waited:.1f} s)"
    return line, {
        "resources": asked,
        "resources_waited": f"{held.waited:.3f}",
        "capacity": capacity,
    }


#: The suite property holding the settings' notes (IDs left out of the default pool, ...).
SETTINGS_NOTES = "settings_notes"
NOTES_SEPARATOR = " | "


def summary(
    policy: environment.Policy,
    domain_id: int | None,
    config: settings.Settings | None = None,
    reserved: bool = True,
) -> tuple[list[str], dict[str, str]]:
    """What a run on ``domain_id`` (None: isolation disabled) says first, and its properties.

    One wording for the runner's output and the pytest plugin's header. ``config``'s
    notes concern the pool, so they are said only when an ID was handed out.
    ``reserved``: False for a test in namespaces that runs on an ID it does not hold.
    """
    lines: list[str] = []
    properties: dict[str, str] = {}
    if domain_id is not None:
        properties["ros_domain_id"] = str(domain_id)
        if policy.discovery is not None:
            lines.append(policy.discovery.describe())
            if not policy.namespaces:  # in namespaces, static peers are loopback only
                lines.extend(policy.discovery.warnings)
            properties.update(policy.discovery.properties())
        # Gazebo's transport ignores the domain: its own partition, said beside it.
        gz_name = policy.partition_for(domain_id)
        lines.append(partition.describe(gz_name))
        properties[partition.PROPERTY] = gz_name or f"not set ({partition.OPT_OUT_ENV}=off)"
        more, isolated = isolation_summary(policy, domain_id, reserved)
        lines.extend(more)
        properties.update(isolated)
        if config is not None and config.notes:
            lines.extend(config.notes)
            properties[SETTINGS_NOTES] = NOTES_SEPARATOR.join(config.notes)
    else:
        properties["ros_domain_id"] = policy.env.get(environment.DOMAIN_VAR, "unset (0)")
        properties["isolation"] = "disabled"
        preset = [policy.env[name] for name in partition.VARIABLES if name in policy.env]
        properties[partition.PROPERTY] = preset[0] if preset else "unset"
    lines.extend(policy.notes)
    return lines, properties


def isolation_summary(
    policy: environment.Policy, domain_id: int, reserved: bool
) -> tuple[list[str], dict[str, str]]:
    """The lines and properties saying how the test is kept apart, unless by default.

    Domain isolation asked for by nobody (the default) says nothing new: results look
    as they always did.
    """
    if policy.namespaces:
        from ros_isolated_test.process import namespace

        lines = [
            "isolation namespace: network (loopback only), mount (a private /dev/shm) and "
            f"IPC namespaces of its own, in a user namespace as {namespace.describe_user()}: "
            "nothing it binds or sends reaches another test"
        ]
        mode = "namespace" if policy.mode == "namespace" else "namespace (auto)"
        properties = {"isolation": mode}
        if reserved:
            properties["ros_domain_id_reserved"] = "yes"
        else:
            why = "no ID of the pool is free (in use, or waited for by queued runners)"
            lines.append(
                f"ROS_DOMAIN_ID {domain_id} is not reserved: {why}; the test runs at once "
                "on it, isolated by its namespaces"
            )
            properties["ros_domain_id_reserved"] = f"no: {why}; the namespaces isolate the test"
        return lines, properties
    if policy.fallback is not None:
        return (
            [f"isolation auto: by the domain ID alone, {policy.fallback}"],
            {"isolation": f"domain (auto: {policy.fallback})"},
        )
    if policy.mode != "domain":
        return [], {"isolation": policy.mode}
    return [], {}


def leftover_note(leftover: str) -> str:
    """The line naming a process the work left running, ended by the sweep."""
    return f"stopped process {leftover}, left running by the test"


class Interrupted(Exception):
    """A signal ended the run before the test started (while waiting for an ID)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


class _Guard:
    """Whether the test has started: a signal after that must not say it never ran."""

    def __init__(self) -> None:
        self.test_started = False
        #: The run is writing its final word (a "not run" result): signals only noted.
        self.concluding = False
        self.late: int | None = None
        #: Where a late signal is noted, once the test has ended.
        self.result: ResultFile | None = None

    def start(self) -> None:
        """Called by the supervisor once the test exists, while its own handlers are in place.

        Not before: a signal until then finds the test not started and ends the run
        cleanly, saying it never ran, rather than being noted while the test runs in full.
        """
        self.test_started = True

    def note_late(self) -> None:
        """The test had ended: the run's outcome stands, the signal is only noted."""
        if self.late is not None and self.result is not None:
            self.result.properties["signal_after_test"] = exit_codes.signal_name(self.late)


@contextlib.contextmanager
def _interruptible(guard: _Guard) -> Iterator[None]:
    """Until the final result is written, SIGINT/SIGTERM/SIGHUP never end the runner abruptly.

    Before the test starts (a runner queued for an ID; PID 1, which has no default
    action) a signal ends the run cleanly, with a result saying it never ran. While the
    test runs, the supervisor's own handlers pass it on. After that (the ID being
    released, the result file being written) it is only noted. Outside the main thread
    (an embedding program) handlers cannot be set: the program's own stay.
    """

    def stop(signum: int, _frame: FrameType | None) -> None:
        if guard.test_started or guard.concluding:
            if guard.late is None:
                guard.late = signum
                guard.note_late()
            return
        guard.concluding = True
        raise Interrupted(signum)

    previous = supervisor.set_handlers(stop)
    try:
        yield
    finally:
        supervisor.restore_handlers(previous)


class Held:
    """The ID held for the work, and what of the work's processes outlived it."""

    __slots__ = ("domain_id", "reserved", "resources", "survivors", "waited", "waited_resources")

    def __init__(
        self,
        domain_id: int | None,
        resources: dict[str, int] | None = None,
        waited: float = 0.0,
        waited_resources: float = 0.0,
        reserved: bool = True,
    ) -> None:
        #: None only for resources held with isolation disabled.
        self.domain_id = domain_id
        #: False for a test in namespaces of its own that found no ID free: it runs on
        #: ``domain_id`` without holding it (its namespaces keep it apart).
        self.reserved = reserved
        #: The machine resources held with it ({} for none), how long the wait was, and
        #: how much of it the resources were short (the rest: no ID).
        self.resources = resources or {}
        self.waited = waited
        self.waited_resources = waited_resources
        #: The supervisor's survivors once it returned: the authoritative list, the one
        #: the result names. None until then: a run that ended otherwise scans afresh.
        self.survivors: Sequence[proc.Stat] | None = None


@contextlib.contextmanager
def isolation(
    policy: environment.Policy,
    config: settings.Settings,
    command: Sequence[str],
    note: Callable[[str], None],
    sweep_grace: float | None = None,
) -> Iterator[Held | None]:
    """Hold a domain ID for the ``with`` block (None: isolation disabled), then release it.

    With ``sweep_grace`` (work that ran in this process, the pytest plugin) this process
    adopts orphans for the block, and after it the supervisor's sweep ends every process
    the work left in its tree (SIGTERM, ``sweep_grace`` seconds, then SIGKILL), naming
    each; processes that were children before the block are not the work's, and stay.
    Either way, what survives keeps the ID blocked, and only then is the ID released.
    The resources ``config`` asks for are held with the ID, and without one when
    isolation is disabled (a GPU is as scarce either way); survivors keep them held too.
    In namespace mode no ID is waited for (one free is held, else the pool's first is
    used unreserved: ``held.reserved``); resources are waited for as ever. Work in this
    very process enters the namespaces here, once the reservation has looked at the
    host's network (ports, participants). Raises PoolExhaustedError or LockDirError when
    no ID can be had, CapacityConflictError when runners disagree, NamespaceError when
    this process cannot enter its namespaces.
    """
    if not policy.isolate and not config.resources:
        yield None
        return
    others: frozenset[tuple[int, int]] = frozenset()
    adopted = False
    if sweep_grace is not None:
        # Ours for the block only: an embedding program is given back as it was.
        adopted = not reaper.is_subreaper() and reaper.become_subreaper()
        others = supervisor.existing_children()
    try:
        held, taken = _take(policy, config, command, note)
        try:
            if policy.namespaces and sweep_grace is not None:
                from ros_isolated_test.process import namespace

                namespace.enter_here()
            yield held
        finally:
            try:
                if sweep_grace is not None:
                    # The supervisor's own sweep, as after a test it ran: one way to end a tree.
                    leftovers, held.survivors = supervisor.end_leftovers(sweep_grace, others)
                    for leftover in leftovers:
                        note(leftover_note(leftover))
                _block_survivors(taken, held, note)
            finally:
                taken.release()
    finally:
        if adopted:
            reaper.stop_subreaper()


class _Taken:
    """What a run holds: an ID, resources, or (namespace mode) each apart; let go together."""

    __slots__ = ("parts",)

    def __init__(self, *parts: Reservation | ResourceHold) -> None:
        self.parts = list(parts)

    def block_for(self, processes: Sequence[proc.Stat]) -> Path | None:
        """Keep every part held while ``processes`` live; the first record (None: nothing held)."""
        records = [part.block_for(processes) for part in self.parts]
        return records[0] if records else None

    def release(self) -> None:
        for part in reversed(self.parts):
            part.release()


def _take(
    policy: environment.Policy,
    config: settings.Settings,
    command: Sequence[str],
    note: Callable[[str], None],
) -> tuple[Held, _Taken]:
    """Reserve what the run needs: an ID (waiting, unless in namespaces), the resources."""
    coordinator = DomainCoordinator(config.lock_dir, config.pool, config.resources, config.capacity)
    if not policy.isolate:
        hold = coordinator.hold_resources(command, config.wait_timeout, note)
        return Held(None, config.resources, hold.waited, hold.waited_resources), _Taken(hold)
    if not policy.namespaces:
        taken = coordinator.acquire(command, config.wait_timeout, note)
        held = Held(taken.domain_id, config.resources, taken.waited, taken.waited_resources)
        return held, _Taken(taken)
    parts = _Taken()
    waited = (0.0, 0.0)
    try:
        if config.resources:
            hold = coordinator.hold_resources(command, config.wait_timeout, note)
            parts.parts.append(hold)
            waited = (hold.waited, hold.waited_resources)
        reservation = DomainCoordinator(config.lock_dir, config.pool).reserve_if_free(command)
    except BaseException:
        parts.release()
        raise
    if reservation is None:
        # Any ID will do in a network of its own: the pool's first, said to be shared.
        return Held(config.pool[0], config.resources, *waited, reserved=False), parts
    parts.parts.append(reservation)
    return Held(reservation.domain_id, config.resources, *waited), parts


def _block_survivors(taken: _Taken, held: Held, note: Callable[[str], None]) -> None:
    """What of the work's tree still lives keeps the ID and the resources until it is gone.

    Not ours to kill, or stuck in the kernel. The supervisor's own list when it returned
    (never a process of an embedding program); a scan of our tree only when it did not
    (an error in the runner).
    """
    survivors = held.survivors
    if survivors is None:
        survivors = supervisor.survivors()
    if not survivors:
        return
    from ros_isolated_test.domain_coordinator.resources import describe

    if not taken.parts:
        return  # nothing held (namespace mode, no ID free): named above, nothing to keep
    names = ", ".join(survivor.describe() for survivor in survivors)
    own_id = held.domain_id is not None and held.reserved
    kept = [f"ROS_DOMAIN_ID {held.domain_id}"] if own_id else []
    kept += [describe(held.resources)] if held.resources else []
    what = " and ".join(kept)
    try:
        record = taken.block_for(survivors)
    except OSError as error:
        note(
            f"cannot keep {what} blocked while {names} live: {error}; make the lock "
            "directory writable"
        )
    else:
        verb = "stays" if len(kept) == 1 else "stay"
        where = "" if record is None else f" ({record.name})"
        note(f"{what} {verb} blocked while {names} live{where}; see ros-isolated-test status")


def _conclude(
    request: RunRequest,
    result: ResultFile,
    capture: OutputCapture,
    outcome: supervisor.Outcome,
) -> int:
    """Turn how the test ended into the result file and the exit code (rules: exit_codes)."""
    code, reason = exit_codes.ended(outcome, request.mode is Mode.AMENT, request.timeout)
    result.properties["exit"] = reason
    if outcome.returncode is not None and outcome.returncode >= 0:
        result.properties["exit_code"] = str(outcome.returncode)
    if outcome.signal is not None:
        result.properties["signal"] = exit_codes.signal_name(outcome.signal)
    result.properties["duration"] = f"{outcome.duration:.3f}"
    if outcome.start_error is not None:
        capture.note(f"invocation failed: {outcome.start_error}")
    capture.note(f"the test {reason}")
    _streams_noted(result, capture)
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


def _streams_noted(result: ResultFile, capture: OutputCapture) -> None:
    """What went wrong with the output file (fails a pass) or the console (never does)."""
    if capture.file_error is not None:
        result.properties["output_file_error"] = capture.file_error
    if capture.console_error is not None:
        result.properties["console_error"] = capture.console_error


def _output_lost_case(result: ResultFile, capture: OutputCapture, output_file: Path | None) -> Case:
    """An error case for a test that passed but whose --output-file lost output (full disk)."""
    message = (
        f"{capture.file_error}; so --output-file {output_file} is incomplete "
        "(the console and this result file got the output); free space or choose another path"
    )
    return Case.saying(result.suite_name, "output file", Outcome.ERROR, message)


def report_usage_error(message: str, result_file: Path | None) -> int:
    """Arguments that cannot be understood: say so in one line, still leave a result file."""
    _keep_standard_descriptors()
    # Never run: built-in settings, so a usage error never reads (nor trips on) a variable.
    request = RunRequest((), Mode.AMENT, settings.defaults(), result_file=result_file)
    result = _result_file(request)
    try:
        result.prepare()
    except OSError:
        _error(_console(), message)
        return exit_codes.USAGE
    return _not_run(result, _console(), message, Outcome.ERROR, exit_codes.USAGE)


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
        # sys.stderr is None when it was closed at start: print would write to stdout.
        if sys.stderr is not None:
            print(f"ros-isolated-test: error: {message}", file=sys.stderr, flush=True)


def _open_output(path: Path | None) -> contextlib.AbstractContextManager[BinaryIO | None]:
    """The --output-file, opened for writing; a FIFO without a reader fails at once (ENXIO).

    Opened non-blocking, so a FIFO nobody reads is an error rather than a hang; then
    blocking again (our own descriptor), so a slow reader slows the test, never loses output.
    """
    if path is None:
        return contextlib.nullcontext()
    path.parent.mkdir(parents=True, exist_ok=True)

    def opener(name: str, flags: int) -> int:
        fd = os.open(name, flags | os.O_NONBLOCK, 0o666)
        try:
            os.set_blocking(fd, True)
        except BaseException:
            os.close(fd)
            raise
        return fd

    # Unbuffered: a failing write is seen (and survived) at once, never at close.
    return open(path, "wb", buffering=0, opener=opener)


def _output_message(path: Path | None, error: OSError) -> str:
    """The one-line error for an --output-file that cannot be opened."""
    if error.errno == errno.ENXIO:
        return (
            f"cannot open output file {path}: it is a FIFO that nobody reads; "
            "start its reader first, or choose a regular file path"
        )
    return f"cannot open output file {path}: {error.strerror}; choose a writable file path"
