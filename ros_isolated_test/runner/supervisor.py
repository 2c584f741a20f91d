"""Process supervision: start the test, pump its output, enforce the timeout, report how it ended.

Runs like a shell runs a foreground job: the test stays in the runner's process group
(so a terminal's Ctrl-C reaches it directly and it may read a terminal's stdin),
SIGINT is left to the test, SIGTERM and SIGHUP are passed on to it.
"""

from __future__ import annotations

import contextlib
import os
import selectors
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import FrameType

from ros_isolated_test.runner import process_tree
from ros_isolated_test.runner.capture import OutputCapture

CHUNK_BYTES = 64 * 1024
#: How long to keep draining output after the test exited, while bytes keep coming.
DRAIN_IDLE_SECONDS = 0.2
FORWARDED_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


@dataclass(frozen=True)
class Outcome:
    """How the test ended. Exactly one of ``returncode`` / ``start_error`` is set."""

    returncode: int | None
    duration: float
    timed_out: bool = False
    start_error: OSError | None = None
    #: A signal the runner received and passed on (SIGTERM from ctest, a container stop).
    received_signal: int | None = None

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
    kill_grace: float = 5.0,
) -> Outcome:
    """Run ``command`` to its end, streaming its merged stdout and stderr into ``capture``."""
    start = time.monotonic()
    try:
        process = subprocess.Popen(
            list(command), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=dict(env)
        )
    except OSError as error:
        return Outcome(returncode=None, duration=time.monotonic() - start, start_error=error)
    received: list[int] = []
    restore = _forward_signals(process, received)
    try:
        timed_out = _pump(process, capture, start, timeout, kill_grace)
        returncode = process.wait()
    finally:
        restore()
    return Outcome(
        returncode=returncode,
        duration=time.monotonic() - start,
        timed_out=timed_out,
        received_signal=received[0] if received else None,
    )


def _pump(
    process: subprocess.Popen[bytes],
    capture: OutputCapture,
    start: float,
    timeout: float | None,
    kill_grace: float,
) -> bool:
    """Copy output and enforce the timeout until the test has exited and its output is done.

    Output is done when the pipe closes, or when the test has exited and the pipe has
    gone quiet: a leftover background process holding the pipe must not hold the runner.
    """
    assert process.stdout is not None
    fd = process.stdout.fileno()
    os.set_blocking(fd, False)
    deadline = start + timeout if timeout is not None else None
    kill_at: float | None = None
    timed_out = False
    pipe_open = True
    with selectors.DefaultSelector() as selector:
        selector.register(fd, selectors.EVENT_READ)
        while True:
            now = time.monotonic()
            if deadline is not None and not timed_out and now >= deadline:
                timed_out = True
                _signal(process, signal.SIGTERM)
                kill_at = now + kill_grace
            if kill_at is not None and now >= kill_at:
                _signal(process, signal.SIGKILL)
                kill_at = None
            exited = process.poll() is not None
            if exited and not pipe_open:
                break
            wait = DRAIN_IDLE_SECONDS if exited else 0.5
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
    process.stdout.close()
    return timed_out


def _signal(process: subprocess.Popen[bytes], signum: int) -> None:
    """Signal the test and everything it started, while the test is still there."""
    if process.poll() is None:
        process_tree.signal_tree(process.pid, signum)


def _forward_signals(process: subprocess.Popen[bytes], received: list[int]) -> Callable[[], None]:
    """Install handlers for the test's lifetime; return the function that restores them."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def forward(signum: int, _frame: FrameType | None) -> None:
        received.append(signum)
        _signal(process, signum)

    previous = {sig: signal.signal(sig, forward) for sig in FORWARDED_SIGNALS}
    # Like a shell waiting for its foreground job: Ctrl-C is the test's to handle.
    previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.SIG_IGN)

    def restore() -> None:
        for sig, handler in previous.items():
            signal.signal(sig, handler)

    return restore
