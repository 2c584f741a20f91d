"""One attempt at the test: hold an ID, run it, end its tree, record how it went, release.

What the result records of the attempt (its ID, when it ran, what it waited for, what
it left running) is gathered here, in the order it happens; how the test ended becomes
the result's final word only after the ID is released (``verdict``).
"""

from __future__ import annotations

import os
import time

from ros_isolated_test import names
from ros_isolated_test.domain_coordinator.pool import id_ranges
from ros_isolated_test.process import supervisor
from ros_isolated_test.runner.isolation import isolation, leftover_note
from ros_isolated_test.runner.summary import header_line, resources_summary, summary
from ros_isolated_test.text import shell_join
from ros_isolated_test.xunit.timeline import timeline_properties

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from ros_isolated_test.process.capture import OutputCapture
    from ros_isolated_test.runner import environment, settings
    from ros_isolated_test.runner.interruption import Guard
    from ros_isolated_test.runner.request import RunRequest
    from ros_isolated_test.xunit.result_file import ResultFile


def command_of(request: RunRequest, result: ResultFile, number: int) -> tuple[str, ...]:
    """The command attempt ``number`` runs: its own result file goes beside the result path.

    The result path it names is pointed at ``result.own_file``, so the result path holds
    the placeholder (in a rerun series: the record so far) until the runner, the test
    ended, adopts the attempt: a kill at any moment leaves a failing file, never the
    test's own "passed". A command that names no argument as the result path writes it
    itself, as before (``result.in_place``).
    """
    own = result.own_file(number)
    if own is None:
        return request.command
    command = request.command_writing_to(own)
    if command == request.command:
        result.writes_in_place()
    return command


def attempt(
    request: RunRequest,
    number: int,
    policy: environment.Policy,
    config: settings.Settings,
    result: ResultFile,
    capture: OutputCapture,
    guard: Guard,
) -> tuple[supervisor.Outcome, int | None]:
    """Run the test once on an ID of its own: reserve, run, end its tree, release.

    Returns how the test ended and the ID it ran on (None: isolation disabled). Raises
    PoolExhaustedError or LockDirError (no ID), CapacityConflictError, RefusedError
    (namespaces that cannot be had), or Interrupted (a signal before it started).
    """
    command = policy.wrapped(command_of(request, result, number))
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
        capture.note(f"invoking in '{os.getcwd()}': {shell_join(command)}")
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
            result.properties[names.LEFTOVER_PROCESSES] = ", ".join(outcome.leftovers)
        survivors = [survivor.describe() for survivor in outcome.survivors]
        for survivor in survivors:
            capture.note(f"process {survivor} of the test could not be ended (SIGKILL failed)")
        if survivors:
            result.properties[names.SURVIVING_PROCESSES] = ", ".join(survivors)
    return outcome, domain_id


def _namespaces_refused(outcome: supervisor.Outcome) -> bool:
    """Whether the test could not start because its namespaces could not be made."""
    from ros_isolated_test.process.namespace import NamespaceError

    return isinstance(outcome.start_error, NamespaceError)
