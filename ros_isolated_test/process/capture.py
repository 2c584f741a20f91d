"""Output capture: the test's bytes go live to the console and the output file, by chunks.

Nothing but a bounded tail is kept in memory, so a test printing gigabytes costs the
runner the same memory as one printing a line, and time stays linear. The output file
gets every byte or says where it stopped and why (``file_error``): a full disk never
truncates it silently. The console gets every byte too, even one left non-blocking by
whoever shares it (a write that would block waits for room), unless it fails or its
reader stops reading for :data:`CONSOLE_STALL_SECONDS`: then it gets no more, and
``console_error`` says why (the run goes on: a console never fails a test).
"""

from __future__ import annotations

import contextlib
import os
import select
import stat

from ros_isolated_test.text import shown

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Callable
    from typing import BinaryIO

PREFIX = "-- ros-isolated-test: "
#: Bytes of output kept for the result file: enough to see why a test failed.
DEFAULT_TAIL_BYTES = 64 * 1024
#: A console that takes no byte for this long (a reader that stopped reading a
#: non-blocking pipe) is given up on, so it cannot hold the runner for ever.
CONSOLE_STALL_SECONDS = 60.0
_NEWLINE = b"\n"
#: Why a console stopped whose reader stopped reading.
STALLED = "its reader took no byte"


class _Stopped(Exception):
    """A stream took no more bytes: why, and how many of the last write it took."""

    def __init__(self, reason: str, written: int) -> None:
        super().__init__(reason)
        self.reason = reason
        self.written = written


def _write_all(stream: BinaryIO, data: bytes, wait: Callable[[], bool] | None = None) -> None:
    """Every byte of ``data`` or :class:`_Stopped`.

    An unbuffered file (the output file is one) may take fewer bytes than given without
    raising, as a file system filling up does: the rest is written again, and the retry
    raises the error that stopped it (ENOSPC) or takes nothing more. A write that would
    block (a non-blocking descriptor) calls ``wait`` for room, and stops when it says none
    came.
    """
    view = memoryview(data)
    done = 0
    while done < len(view):
        try:
            count = stream.write(view[done:])
        except BlockingIOError as error:
            # A buffered writer: it took (buffered) this many of the bytes before blocking.
            count = error.characters_written
            if not count:
                _wait_or_stop(wait, done)
                continue
        except (OSError, ValueError) as error:
            raise _Stopped(_why(error), done) from None
        if not count:
            # None (would block) or 0: no progress, so no loop that never ends.
            _wait_or_stop(wait, done)
            continue
        done += count
    while True:
        try:
            stream.flush()
        except BlockingIOError:
            _wait_or_stop(wait, done)
        except (OSError, ValueError) as error:
            raise _Stopped(_why(error), done) from None
        else:
            return


def _wait_or_stop(wait: Callable[[], bool] | None, done: int) -> None:
    """Wait for room to write, or :class:`_Stopped` when none comes."""
    if wait is None:
        raise _Stopped("the file took no more bytes", done)
    if not wait():
        raise _Stopped(STALLED, done)


def _why(error: BaseException) -> str:
    return getattr(error, "strerror", None) or str(error) or type(error).__name__


class OutputCapture:
    """Fans each chunk out to the console and the output file, keeping the last bytes."""

    def __init__(
        self,
        console: BinaryIO,
        output_file: BinaryIO | None = None,
        tail_bytes: int = DEFAULT_TAIL_BYTES,
        console_stall: float = CONSOLE_STALL_SECONDS,
    ) -> None:
        self._console: BinaryIO | None = console
        self._console_stall = console_stall
        #: Bytes that reached the console.
        self.console_bytes = 0
        #: Why the console stopped being written (full, gone, stalled), if it did.
        self.console_error: str | None = None
        self._file = output_file
        self._tail_limit = tail_bytes
        self._tail = bytearray()
        self.total_bytes = 0
        #: Bytes that reached the output file.
        self.file_bytes = 0
        #: Why the output file stopped being written, and how many bytes it holds, if it did.
        self.file_error: str | None = None
        # Whether the last byte each stream got ended a line: runner lines start their own.
        self._console_at_line_start = True
        self._file_at_line_start = True

    def feed(self, chunk: bytes) -> None:
        """Pass one chunk on as it arrived (no line buffering: prompts and dots show at once)."""
        if not chunk:
            return
        self.total_bytes += len(chunk)
        self._to_console(chunk)
        self._to_file(chunk)
        self._tail += chunk
        # Trim only when twice over the limit: amortised O(1) per byte.
        if len(self._tail) > 2 * self._tail_limit:
            del self._tail[: len(self._tail) - self._tail_limit]

    def line(self, text: str) -> None:
        """A line of the runner's own, verbatim (``Running with ROS_DOMAIN_ID 5``).

        It starts on a line of its own in each stream: after a test whose last output had
        no newline, the stream gets one first (never the tail: the test's bytes stay its own).
        """
        # Bytes that were not UTF-8 (a command argument, a folder) as \xNN: never a crash.
        data = shown(f"{text}\n").encode()
        self._to_console(data if self._console_at_line_start else _NEWLINE + data)
        self._to_file(data if self._file_at_line_start else _NEWLINE + data)

    def note(self, text: str) -> None:
        """A runner message, prefixed so it stands apart from the test's output."""
        self.line(PREFIX + text)

    def _to_console(self, data: bytes) -> None:
        stream = self._console
        if stream is None:
            return
        try:
            _write_all(stream, data, self._console_ready)
        except _Stopped as stopped:
            self.console_bytes += stopped.written
            self._console = None
            self._console_failed(stopped.reason)
            return
        self.console_bytes += len(data)
        self._console_at_line_start = data.endswith(_NEWLINE)

    def _console_ready(self) -> bool:
        """Wait until the console takes bytes again; False after ``console_stall`` seconds.

        Its descriptor is left non-blocking: the flag belongs to everyone sharing it.
        """
        try:
            fd = self._console.fileno() if self._console is not None else -1
        except (OSError, ValueError, AttributeError):
            return False
        if fd < 0:
            return False
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        return bool(poller.poll(self._console_stall * 1000))

    def _console_failed(self, reason: str) -> None:
        """Stop the console, never the run: the output file and the result file still get it.

        A reader that went away or stopped reading, a full device: the run's outcome
        is the test's own. Said on stderr, while that works; the session puts it in
        the result file.
        """
        if reason == STALLED:
            reason = f"{reason} for {self._console_stall:g} s"
        self.console_error = (
            f"writing the console failed after {self.console_bytes} bytes: {reason}"
        )
        message = f"{self.console_error}; it gets no more output (the result file keeps the tail)"
        with contextlib.suppress(OSError):
            # One system call, unbuffered: nothing left half-written in a buffer for exit.
            os.write(2, shown(f"{PREFIX}{message}\n").encode())

    def _to_file(self, data: bytes) -> None:
        stream = self._file
        if stream is None:
            return
        try:
            _write_all(stream, data)
        except _Stopped as stopped:
            self.file_bytes += stopped.written
            self._file = None
            self._file_failed(stream, stopped.reason)
            return
        self.file_bytes += len(data)
        self._file_at_line_start = data.endswith(_NEWLINE)

    def _file_failed(self, stream: BinaryIO, reason: str) -> None:
        """Stop the copy, never the run: the console and the result file still get it all."""
        held = self.file_bytes
        try:
            status = os.fstat(stream.fileno())
            if stat.S_ISREG(status.st_mode):
                # What the file really holds: a buffered writer counts bytes it only kept.
                held = status.st_size
        except (OSError, ValueError, AttributeError):
            pass
        name = getattr(stream, "name", None)
        where = f"output file {name}" if isinstance(name, str) else "the output file"
        self.file_error = f"writing {where} failed after {held} bytes: {reason}"
        self.note(f"{self.file_error}; the output continues on the console only")

    @property
    def truncated(self) -> bool:
        """Whether the tail lost the beginning of the output."""
        return self.total_bytes > len(self.tail_bytes())

    def tail_bytes(self) -> bytes:
        """The last ``tail_bytes`` bytes of the test's output."""
        return bytes(self._tail[-self._tail_limit :])

    def tail_text(self) -> str:
        """The tail decoded as run_test.py does: UTF-8, the locale's encoding, else shown."""
        import locale

        data = self.tail_bytes()
        encodings = ["utf-8"]
        preferred = locale.getpreferredencoding(False)
        if preferred.lower().replace("-", "") != "utf8":
            encodings.append(preferred)
        for encoding in encodings:
            try:
                text = data.decode(encoding)
                break
            except (UnicodeDecodeError, LookupError):
                continue
        else:
            # Bad bytes shown as \xNN, never as U+FFFD (which xunit-viewer cannot read).
            text = data.decode("utf-8", errors="backslashreplace")
        if self.truncated:
            cut = self.total_bytes - len(data)
            text = f"[... {cut} earlier bytes of output not kept here ...]\n{text}"
        return text
