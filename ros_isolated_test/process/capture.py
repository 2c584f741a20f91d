"""Output capture: the test's bytes go live to the console and the output file, by chunks.

Nothing but a bounded tail is kept in memory, so a test printing gigabytes costs the
runner the same memory as one printing a line, and time stays linear.
"""

from __future__ import annotations

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from typing import BinaryIO

PREFIX = "-- ros-isolated-test: "
#: Bytes of output kept for the result file: enough to see why a test failed.
DEFAULT_TAIL_BYTES = 64 * 1024


class OutputCapture:
    """Fans each chunk out to the console and the output file, keeping the last bytes."""

    def __init__(
        self,
        console: BinaryIO,
        output_file: BinaryIO | None = None,
        tail_bytes: int = DEFAULT_TAIL_BYTES,
    ) -> None:
        self._console = console
        self._file = output_file
        self._tail_limit = tail_bytes
        self._tail = bytearray()
        self.total_bytes = 0
        #: Why the output file stopped being written, if it did.
        self.file_error: str | None = None

    def feed(self, chunk: bytes) -> None:
        """Pass one chunk on as it arrived (no line buffering: prompts and dots show at once)."""
        self.total_bytes += len(chunk)
        self._emit(chunk)
        self._tail += chunk
        # Trim only when twice over the limit: amortised O(1) per byte.
        if len(self._tail) > 2 * self._tail_limit:
            del self._tail[: len(self._tail) - self._tail_limit]

    def line(self, text: str) -> None:
        """A line of the runner's own, verbatim (``Running with ROS_DOMAIN_ID 5``)."""
        self._emit(f"{text}\n".encode())

    def note(self, text: str) -> None:
        """A runner message, prefixed so it stands apart from the test's output."""
        self.line(PREFIX + text)

    def _emit(self, data: bytes) -> None:
        try:
            self._console.write(data)
            self._console.flush()
        except (OSError, ValueError):
            # A closed console (a reader that went away) must not kill the test's run.
            pass
        if self._file is not None:
            try:
                self._file.write(data)
                self._file.flush()
            except OSError as error:
                # A full disk or a closed pipe ends the copy, never the run: the console
                # and the result file still get everything.
                self._file = None
                self.file_error = f"writing the output file failed: {error.strerror or error}"
                self.note(f"{self.file_error}; output continues on the console only")

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
