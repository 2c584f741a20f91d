"""Process supervision: start the test, pump its output, end its whole tree, report how it ended.

The test stays in the runner's process group, as a shell's foreground job does, so it
may read a terminal's stdin without being stopped by SIGTTIN and a terminal's Ctrl-C
reaches it directly. The runner is a child subreaper: every process the test starts
stays in its tree, and none outlives the run. When the test's main process ends, for
any reason, what is left of the tree gets SIGTERM, then SIGKILL after a grace period,
and only then does the caller release the domain ID.
"""

from __future__ import annotations

import contextlib
import os
import selectors
import signal
import subprocess
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import FrameType

from ros_isolated_test.runner import process_tree, reaper
from ros_isolated_test.runner.capture import OutputCapture

CHUNK_BYTES = 64 * 1024
#: How long to keep draining output after the test exited, while bytes keep coming.
DRAIN_IDLE_SECONDS = 0.2
#: At most this long after the test exited, however much its leftovers keep writing.
DRAIN_LIMIT_SECONDS = 1.0
POLL_SECONDS = 0.2
#: Signals that end a run: passed on to the test, then the same cleanup as a timeout.
FORWARDED_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@dataclass(frozen=True)
class Outcome:
    """How the test ended. Exactly one of ``returncode`` / ``start_error`` is set."""

    returncode: int | None
    duration: float
    timed_out: bool = False
    start_error: OSError | None = None
    #: A signal the runner received and passed on (Ctrl-C, SIGTERM from a container stop).
    received_signal: int | None = None
    #: Processes of the test still alive after its main process ended, then stopped.
    leftovers: tuple[str, ...] = field(default_factory=tuple)

    @property
    def signal(self) -> int | None:
        """The signal that killed the test, if one did."""
        if self.returncode is not None and self.returncode < 0:
            return -self.returncode
        return None


class _Signals:
    """Signal handlers for the test's lifetime: pass the signal on, remember it."""

    def __init__(self) -> None:
        self.received: int | None = None
        self.at: float | None = None
        self._previous: dict[int, object] = {}

    def __enter__(self) -> _Signals:
        if threading.current_thread() is threading.main_thread():
            for signum in FORWARDED_SIGNALS:
                self._previous[signum] = signal.signal(signum, self._forward)
        return self

    def __exit__(self, *_exc: object) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)  # type: ignore[arg-type]

    def _forward(self, signum: int, _frame: FrameType | None) -> None:
        if self.received is None:
            self.received, self.at = signum, time.monotonic()
        targets = process_tree.descendants(os.getpid())
        if signum == signal.SIGINT and _from_terminal():
            # The terminal already sent it to our process group: only processes that
            # left the group (setsid daemons) still need it, and only once.
            group = os.getpgrp()
            targets = [target for target in targets if target.pgid != group]
        process_tree.signal_all(targets, signum)


def _from_terminal() -> bool:
    """Whether our group is a terminal's foreground group (so Ctrl-C reached all of it)."""
    for fd in (0, 1, 2):
        with contextlib.suppress(OSError):
            return os.tcgetpgrp(fd) == os.getpgrp()
    return False


def run(
    command: Sequence[str],
    env: Mapping[str, str],
    capture: OutputCapture,
    timeout: float | None = None,
    kill_grace: float = 5.0,
) -> Outcome:
    """Run ``command`` to its end and its tree's end, streaming its output into ``capture``."""
    reaper.become_subreaper()
    start = time.monotonic()
    # Handlers before the test exists: a signal arriving as it starts must reach it too.
    with _Signals() as signals:
        try:
            process = subprocess.Popen(
                list(command), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=dict(env)
            )
        except OSError as error:
            return Outcome(returncode=None, duration=time.monotonic() - start, start_error=error)
        if signals.received is not None:
            # It came while the test was being started, before it could be passed on.
            process_tree.signal_tree(process.pid, signals.received)
        try:
            timed_out = _pump(process, capture, start, timeout, kill_grace, signals)
        except BaseException:
            # Whatever went wrong in the runner, the test must not outlive it unseen.
            process_tree.signal_tree(process.pid, signal.SIGKILL)
            process.wait()
            _end_leftovers(0.0)
            raise
        returncode = process.wait()
        leftovers = _end_leftovers(kill_grace)
        _drain(process, capture)
    return Outcome(
        returncode=returncode,
        duration=time.monotonic() - start,
        timed_out=timed_out,
        received_signal=signals.received,
        leftovers=leftovers,
    )


def _pump(
    process: subprocess.Popen[bytes],
    capture: OutputCapture,
    start: float,
    timeout: float | None,
    kill_grace: float,
    signals: _Signals,
) -> bool:
    """Copy output until the test exited and its output is done; enforce the timeout.

    Output is done when the pipe closes, or when the test has exited and the pipe has
    gone quiet: a leftover background process holding the pipe must not hold the runner.
    A timeout (or a signal the runner passed on) gives the test ``kill_grace`` seconds
    after SIGTERM before SIGKILL.
    """
    assert process.stdout is not None
    fd = process.stdout.fileno()
    os.set_blocking(fd, False)
    deadline = start + timeout if timeout is not None else None
    kill_at: float | None = None
    timed_out = False
    pipe_open = True
    drain_until: float | None = None
    with selectors.DefaultSelector() as selector:
        selector.register(fd, selectors.EVENT_READ)
        while True:
            now = time.monotonic()
            if deadline is not None and not timed_out and now >= deadline:
                timed_out = True
                _signal(process, signal.SIGTERM)
                kill_at = now + kill_grace
            if signals.at is not None and kill_at is None and not timed_out:
                kill_at = signals.at + kill_grace
            if kill_at is not None and now >= kill_at:
                _signal(process, signal.SIGKILL)
            reaper.reap_orphans(keep=process.pid)
            exited = process.poll() is not None
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
                with contextlib.suppress(subprocess.TimeoutExpired):
                    process.wait(wait)
                continue
            if not selector.select(wait):
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
                selector.unregister(fd)
    return timed_out


def _signal(process: subprocess.Popen[bytes], signum: int) -> None:
    """Signal the test and everything it started, while the test is still there."""
    if process.poll() is None:
        process_tree.signal_tree(process.pid, signum)


def _end_leftovers(grace: float) -> tuple[str, ...]:
    """SIGTERM what is left of the test's tree, SIGKILL it after ``grace``; reap it all.

    Returns a description of each process that had to be stopped.
    """
    me = os.getpid()
    leftovers = process_tree.descendants(me)
    if not leftovers:
        reaper.reap_orphans()
        return ()
    process_tree.signal_all(leftovers, signal.SIGTERM)
    deadline = time.monotonic() + grace
    while time.monotonic() < deadline:
        reaper.reap_orphans()
        if not process_tree.descendants(me):
            break
        time.sleep(0.05)
    else:
        process_tree.signal_all(process_tree.descendants(me), signal.SIGKILL)
        while process_tree.descendants(me) and time.monotonic() < deadline + 5:
            reaper.reap_orphans()
            time.sleep(0.02)
    reaper.reap_orphans()
    return tuple(f"{item.pid} ({item.name})" for item in leftovers)


def _drain(process: subprocess.Popen[bytes], capture: OutputCapture) -> None:
    """Take what the stopped leftovers wrote, without waiting; then close the pipe."""
    assert process.stdout is not None
    fd = process.stdout.fileno()
    with contextlib.suppress(OSError, ValueError):
        while chunk := os.read(fd, CHUNK_BYTES):
            capture.feed(chunk)
    process.stdout.close()
