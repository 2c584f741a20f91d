"""Process supervision: start the test, pump its output, end its whole tree, report how it ended.

The test stays in the runner's process group, as a shell's foreground job does, so it
may read a terminal's stdin without being stopped by SIGTTIN and a terminal's Ctrl-C
reaches it directly. The runner is a child subreaper: every process the test starts
stays in its tree, and none outlives the run. Only once the tree is empty does the
caller release the domain ID; what outlives even the sweep is reported as a survivor.

This module is the run loop and its :class:`Outcome`; the steps it drives live apart:
``spawn`` starts the test, ``signals`` passes the runner's signals on to it, ``sweep``
ends what it left running.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import time
from collections.abc import Callable, Mapping, Sequence

from ros_isolated_test.process import proc, reaper, tree
from ros_isolated_test.process.capture import OutputCapture
from ros_isolated_test.process.signals import Signals
from ros_isolated_test.process.spawn import STATUS_LOST, Test, child_statuses_kept
from ros_isolated_test.process.sweep import end_leftovers, existing_children

CHUNK_BYTES = 64 * 1024
#: How long to keep draining output after the test exited, while bytes keep coming.
DRAIN_IDLE_SECONDS = 0.2
#: At most this long after the test exited, however much its leftovers keep writing.
DRAIN_LIMIT_SECONDS = 1.0
POLL_SECONDS = 0.2
#: Seconds a test (and what it left running) gets to exit on SIGTERM before SIGKILL.
KILL_GRACE = 5.0


class Outcome:
    """How the test ended. Exactly one of ``returncode`` / ``start_error`` is set."""

    __slots__ = (
        "duration",
        "leftovers",
        "received_signal",
        "returncode",
        "start_error",
        "survivors",
        "timed_out",
    )

    def __init__(
        self,
        returncode: int | None,
        duration: float,
        timed_out: bool = False,
        start_error: OSError | None = None,
        received_signal: int | None = None,
        leftovers: tuple[str, ...] = (),
        survivors: tuple[proc.Stat, ...] = (),
    ) -> None:
        self.returncode = returncode
        self.duration = duration
        self.timed_out = timed_out
        self.start_error = start_error
        #: A signal the runner received and passed on (Ctrl-C, SIGTERM from a container stop).
        self.received_signal = received_signal
        #: Processes of the test still alive after its main process ended, then stopped.
        self.leftovers = leftovers
        #: Processes of the test that even SIGKILL did not end (not ours to signal, stuck
        #: in the kernel): alive after the run, so the caller keeps the ID blocked.
        self.survivors = survivors

    @property
    def signal(self) -> int | None:
        """The signal that killed the test, if one did."""
        if self.returncode is not None and self.returncode < 0:
            return -self.returncode
        return None


def run(
    command: Sequence[str],
    env: Mapping[str, str],
    capture: OutputCapture,
    timeout: float | None = None,
    kill_grace: float = KILL_GRACE,
    on_start: Callable[[], None] | None = None,
    namespaces: bool = False,
) -> Outcome:
    """Run ``command`` to its end and its tree's end, streaming its output into ``capture``.

    ``on_start`` is called once the test exists, while this function's signal handlers
    are in place: the caller learns the test started with no window for a signal between.
    ``namespaces``: start it in user, network, mount and IPC namespaces of its own
    (``namespace``); its processes stay in the runner's PID namespace and tree, so they
    are ended exactly as in domain mode.
    """
    reaper.become_subreaper()
    start = time.monotonic()
    others = existing_children()
    # Handlers before the test exists: a signal arriving as it starts must reach it too.
    with child_statuses_kept(), Signals(others) as signals:
        try:
            test = Test(command, env, namespaces)
        except OSError as error:
            return Outcome(returncode=None, duration=time.monotonic() - start, start_error=error)
        if on_start is not None:
            on_start()
        try:
            if signals.received is not None:
                # It came while the test was being started, before it could be passed on.
                tree.signal_tree(test.pid, signals.received)
            try:
                timed_out = _pump(test, capture, start, timeout, kill_grace, signals, others)
            except BaseException:
                # Whatever went wrong in the runner, the test must not outlive it unseen.
                tree.signal_tree(test.pid, signal.SIGKILL)
                test.wait()
                end_leftovers(0.0, others)
                raise
            returncode = test.wait()
            leftovers, survived = end_leftovers(kill_grace, others)
            _drain(test, capture)
            if test.status_lost:
                capture.note(
                    f"the test's exit status was lost (reaped elsewhere: SIGCHLD ignored?);"
                    f" counted as exit code {STATUS_LOST}"
                )
        finally:
            os.close(test.stdout)
    assert returncode is not None
    return Outcome(
        returncode=returncode,
        duration=time.monotonic() - start,
        timed_out=timed_out,
        received_signal=signals.received,
        leftovers=leftovers,
        survivors=survived,
    )


def _pump(
    test: Test,
    capture: OutputCapture,
    start: float,
    timeout: float | None,
    kill_grace: float,
    signals: Signals,
    others: frozenset[tuple[int, int]],
) -> bool:
    """Copy output until the test exited and its output is done; enforce the timeout.

    Output is done when the pipe closes, or when the test has exited and the pipe has
    gone quiet: a leftover background process holding the pipe must not hold the runner.
    A timeout (or a signal the runner passed on) gives the test ``kill_grace`` seconds
    after SIGTERM before SIGKILL.
    """
    fd = test.stdout
    os.set_blocking(fd, False)
    deadline = start + timeout if timeout is not None else None
    kill_at: float | None = None
    timed_out = False
    pipe_open = True
    drain_until: float | None = None
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    while True:
        now = time.monotonic()
        if deadline is not None and not timed_out and now >= deadline:
            timed_out = True
            _signal(test, signal.SIGTERM)
            kill_at = now + kill_grace
        if signals.at is not None and kill_at is None and not timed_out:
            kill_at = signals.at + kill_grace
        if kill_at is not None and now >= kill_at:
            _signal(test, signal.SIGKILL)
        reaper.reap_orphans(keep=test.pid, spare=others)
        exited = test.poll() is not None
        if exited and drain_until is None:
            drain_until = now + DRAIN_LIMIT_SECONDS
        if exited and (not pipe_open or now >= (drain_until or now)):
            # A leftover that keeps printing must not hold the runner: it is stopped
            # next, and what it wrote by then is drained.
            break
        wait = DRAIN_IDLE_SECONDS if exited else POLL_SECONDS
        for limit in (None if timed_out else deadline, kill_at):
            if limit is not None:
                wait = min(wait, max(0.0, limit - now))
        if not pipe_open:
            test.wait(wait)
            continue
        if not poller.poll(wait * 1000):
            if exited:
                break
            continue
        try:
            chunk = os.read(fd, CHUNK_BYTES)
        except BlockingIOError:
            continue
        if chunk:
            capture.feed(chunk)
        else:
            pipe_open = False
            poller.unregister(fd)
    return timed_out


def _signal(test: Test, signum: int) -> None:
    """Signal the test and everything it started, while the test is still there."""
    if test.poll() is None:
        tree.signal_tree(test.pid, signum)


def _drain(test: Test, capture: OutputCapture) -> None:
    """Take what the stopped leftovers wrote, without waiting."""
    with contextlib.suppress(OSError, ValueError):
        while chunk := os.read(test.stdout, CHUNK_BYTES):
            capture.feed(chunk)
