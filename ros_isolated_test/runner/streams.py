"""Where a run's words go: the console, the --output-file, and the one error line on stderr.

Apart from the session because each is a small fight with the operating system (a
closed descriptor, a FIFO nobody reads, a console that stalls) that the run's steps
never need to read: they get streams that work, or one line saying why not.
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys

from ros_isolated_test.process.capture import OutputCapture

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from pathlib import Path
    from typing import BinaryIO


def keep_standard_descriptors() -> None:
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


def console() -> BinaryIO:
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


def error(console: BinaryIO, message: str) -> None:
    """One line on stderr, where CI and humans look for errors; flushed after stdout."""
    with contextlib.suppress(OSError, ValueError):
        console.flush()
    with contextlib.suppress(OSError, ValueError):
        # A reader that went away (ctest killed by the same Ctrl-C) loses nothing here:
        # everything this says is in the result file already.
        # sys.stderr is None when it was closed at start: print would write to stdout.
        if sys.stderr is not None:
            print(f"ros-isolated-test: error: {message}", file=sys.stderr, flush=True)


class Streams:
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


def open_output(path: Path | None) -> contextlib.AbstractContextManager[BinaryIO | None]:
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


def output_message(path: Path | None, failure: OSError) -> str:
    """The one-line error for an --output-file that cannot be opened."""
    if failure.errno == errno.ENXIO:
        return (
            f"cannot open output file {path}: it is a FIFO that nobody reads; "
            "start its reader first, or choose a regular file path"
        )
    return f"cannot open output file {path}: {failure.strerror}; choose a writable file path"
