"""A test whose runner is SIGKILLed alone: does the test end, or live on as an orphan?

Watched by events, never by a clock: a pidfd, opened while the test's PID is surely its
own, becomes readable the instant the process exits; a live orphan proves it lives by
answering a signal (:data:`ANSWERS_USR1`). The deadline only stops a hung test.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
from pathlib import Path

import pytest

from helpers.processes import DEADLINE, wait_for

#: A test that lives until killed; on SIGUSR1 it writes "alive" to the file named by $0.
#: It writes "$0.ready" once the trap is set: a SIGUSR1 before would end it.
ANSWERS_USR1 = 'trap \'echo alive > "$0"\' USR1; : > "$0.ready"; while :; do sleep 0.05; done'


def ready(answer: Path) -> None:
    """Wait until the test running :data:`ANSWERS_USR1` for ``answer`` can answer."""
    wait_for(answer.with_name(f"{answer.name}.ready"))


def watch(pid: int) -> int:
    """A pidfd for ``pid``, opened before anything may end it (so never a recycled PID)."""
    return os.pidfd_open(pid)


def ended(pidfd: int) -> bool:
    """Whether the process of ``pidfd`` has exited (waited for up to the hang stopper)."""
    ready, _, _ = select.select([pidfd], [], [], DEADLINE)
    return bool(ready)


def wait_ended(pidfd: int, pid: int, what: str) -> None:
    """Fail unless process ``pid`` (``pidfd``) exits; reap it if it became our child."""
    try:
        if not ended(pidfd):
            pytest.fail(f"{what} (pid {pid}) still runs {DEADLINE} s after its runner died")
    finally:
        os.close(pidfd)
    with contextlib.suppress(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # pytest adopts orphans while it is a subreaper


def lives_on(pid: int, answer: Path) -> None:
    """Fail unless process ``pid`` (running :data:`ANSWERS_USR1`) still answers; then end it."""
    try:
        os.kill(pid, signal.SIGUSR1)
        wait_for(answer)
        assert answer.read_text() == "alive\n"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def in_background(command: list[str]) -> list[str]:
    """``command`` as a child of a shell the runner starts: it outlives a runner killed alone.

    The runner's own child dies with it (the death signal set between fork and exec), so a
    test that must show what an orphan does after its runner's death runs one level
    down, as a test's own child or daemon would.
    """
    return ["sh", "-c", '"$@" & wait', "sh", *command]
