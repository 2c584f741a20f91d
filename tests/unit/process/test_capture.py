"""Output capture: the test's bytes go live to the console and the output file, by chunks.

``OutputCapture`` keeps nothing but a bounded tail in memory, so a test printing
gigabytes costs the runner the same memory as one printing a line; the tail says where
it was cut, and decodes even when cut inside a character. The output file gets every
byte or says where it stopped and why (``file_error``): a write error never truncates it
silently. The console gets every byte too, even one left non-blocking by whoever shares
it, unless it fails or its reader stops reading: then it gets no more, ``console_error``
says why, and the run goes on. Runner lines start on a line of their own in every
stream, show bytes that are not UTF-8 as escapes, and never enter the tail. Real files,
pipes and /dev/full (always ENOSPC); each failure has its control.
"""

from __future__ import annotations

import io
import os
import threading
import time
from pathlib import Path

from helpers.output_capture import NO_SPACE

from ros_isolated_test.process.capture import PREFIX, OutputCapture

# --- every chunk passed on, a bounded tail kept -----------------------------------------


def test_capture_passes_every_chunk_on_and_keeps_a_bounded_tail(tmp_path: Path) -> None:
    console = io.BytesIO()
    with open(tmp_path / "out.log", "wb") as log:
        capture = OutputCapture(console, log, tail_bytes=16)
        chunks = [bytes([65 + i % 26]) * (i + 1) for i in range(50)]
        for chunk in chunks:
            capture.feed(chunk)
            assert len(capture.tail_bytes()) <= 16
    everything = b"".join(chunks)
    assert console.getvalue() == everything
    assert (tmp_path / "out.log").read_bytes() == everything
    assert capture.total_bytes == len(everything)
    assert capture.tail_bytes() == everything[-16:]
    assert capture.truncated


def test_capture_tail_text_marks_the_cut() -> None:
    capture = OutputCapture(io.BytesIO(), tail_bytes=10)
    capture.feed(b"0123456789" * 3 + b"tail-end!!")
    text = capture.tail_text()
    assert text == "[... 30 earlier bytes of output not kept here ...]\ntail-end!!"


def test_capture_short_output_is_kept_whole_without_marker() -> None:
    capture = OutputCapture(io.BytesIO(), tail_bytes=100)
    capture.feed(b"hello ")
    capture.feed(b"world\n")
    assert not capture.truncated
    assert capture.tail_text() == "hello world\n"


def test_capture_tail_cut_inside_a_utf8_character_still_decodes() -> None:
    capture = OutputCapture(io.BytesIO(), tail_bytes=5)
    capture.feed("ääää".encode())  # 8 bytes: the tail starts mid-character
    text = capture.tail_text()
    assert text.startswith("[... 3 earlier bytes")
    assert text.endswith("ää")


def test_capture_notes_go_out_but_not_into_the_tail() -> None:
    console = io.BytesIO()
    capture = OutputCapture(console)
    capture.line("Running with ROS_DOMAIN_ID 5")
    capture.note("the test exited with code 0")
    capture.feed(b"test output\n")
    expected = f"Running with ROS_DOMAIN_ID 5\n{PREFIX}the test exited with code 0\ntest output\n"
    assert console.getvalue() == expected.encode()
    assert capture.tail_text() == "test output\n"


class _GoneConsole(io.RawIOBase):
    def writable(self) -> bool:
        return True

    def write(self, data: object) -> int:
        raise BrokenPipeError


def test_capture_survives_a_console_that_went_away(tmp_path: Path) -> None:
    with open(tmp_path / "out.log", "wb") as log:
        capture = OutputCapture(_GoneConsole(), log)  # type: ignore[arg-type]
        capture.feed(b"still ")
        capture.note("recorded")
        capture.feed(b"captured\n")
    assert (tmp_path / "out.log").read_bytes() == f"still \n{PREFIX}recorded\ncaptured\n".encode()
    assert capture.tail_text() == "still captured\n"


# --- runner lines: a line of their own, never in the tail --------------------------------


def test_runner_lines_after_a_line_without_newline_start_a_line_of_their_own(
    tmp_path: Path,
) -> None:
    console = io.BytesIO()
    with open(tmp_path / "out.log", "wb", buffering=0) as log:
        capture = OutputCapture(console, log)
        capture.feed(b"no newline")
        capture.note("first")
        capture.feed(b"more")
        capture.line("Running with ROS_DOMAIN_ID 5")
        capture.feed(b"end\n")
        capture.note("second")
    expected = (
        f"no newline\n{PREFIX}first\nmore\nRunning with ROS_DOMAIN_ID 5\nend\n{PREFIX}second\n"
    ).encode()
    assert console.getvalue() == expected
    assert (tmp_path / "out.log").read_bytes() == expected
    assert capture.tail_bytes() == b"no newlinemoreend\n", "the test's bytes stay its own"


def test_runner_lines_show_bytes_that_are_not_utf8_as_escapes() -> None:
    console = io.BytesIO()
    capture = OutputCapture(console)
    capture.note("invoking: echo " + os.fsdecode(b"caf\xe9"))  # as Python carries argv
    capture.note("a JSON lone surrogate \ud800 and caf\u00e9")
    assert (
        console.getvalue()
        == (
            f"{PREFIX}invoking: echo caf\\xe9\n{PREFIX}a JSON lone surrogate \\ud800 and café\n"
        ).encode()
    )


# --- a file that takes no more: /dev/full (always ENOSPC) ------------------------------------


def test_a_write_error_stops_the_file_says_why_and_the_console_gets_everything() -> None:
    console = io.BytesIO()
    with open("/dev/full", "wb", buffering=0) as full:
        capture = OutputCapture(console, full)
        capture.feed(b"first line\npartial")
        capture.feed(b" rest\n")
        capture.note("the test exited with code 0")
    assert capture.file_error is not None
    assert NO_SPACE in capture.file_error
    assert "/dev/full" in capture.file_error
    assert "after 0 bytes" in capture.file_error
    assert (
        console.getvalue()
        == (
            f"first line\npartial\n{PREFIX}{capture.file_error}; the output continues on the "
            f"console only\n rest\n{PREFIX}the test exited with code 0\n"
        ).encode()
    )
    assert capture.tail_bytes() == b"first line\npartial rest\n"


def test_control_a_file_with_room_gets_everything_and_no_error(tmp_path: Path) -> None:
    console = io.BytesIO()
    with open(tmp_path / "out.log", "wb", buffering=0) as log:
        capture = OutputCapture(console, log)
        capture.feed(b"first line\npartial")
        capture.feed(b" rest\n")
    assert capture.file_error is None
    assert capture.file_bytes == len(b"first line\npartial rest\n")
    assert (tmp_path / "out.log").read_bytes() == console.getvalue()


# --- a non-blocking console: wait for room, give up on a reader that never reads -------------


def test_a_console_whose_reader_never_reads_is_given_up_and_the_file_gets_everything(
    tmp_path: Path,
) -> None:
    """Bounded: a non-blocking pipe nobody reads must not hold the runner for ever."""
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    chunk = b"y" * 1000 + b"\n"
    try:
        with (
            open(write_end, "wb", buffering=0, closefd=False) as console,
            open(tmp_path / "out.log", "wb", buffering=0) as log,
        ):
            capture = OutputCapture(console, log, console_stall=0.3)
            for _ in range(200):  # 200 KB: far more than the pipe holds
                capture.feed(chunk)
            capture.note("the test exited with code 0")
        assert capture.console_error is not None
        assert "took no byte for 0.3 s" in capture.console_error
        assert f"after {capture.console_bytes} bytes" in capture.console_error
        held = b""
        while True:
            try:
                held += os.read(read_end, 1 << 16)
            except BlockingIOError:
                break
            os.set_blocking(read_end, False)
        assert len(held) == capture.console_bytes < 200 * len(chunk)
        logged = (tmp_path / "out.log").read_bytes()
        note = f"{PREFIX}the test exited with code 0\n".encode()
        assert logged == chunk * 200 + note, "the output file lost nothing"
    finally:
        os.close(read_end)
        os.close(write_end)


def test_control_a_non_blocking_console_that_is_read_gets_every_byte() -> None:
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    chunk = b"z" * 1000 + b"\n"
    received = bytearray()

    def drain() -> None:
        time.sleep(0.2)  # late: the pipe is full by then, and writes would block
        while data := os.read(read_end, 1 << 16):
            received.extend(data)

    reader = threading.Thread(target=drain)
    reader.start()
    try:
        with open(write_end, "wb", buffering=0) as console:
            capture = OutputCapture(console, console_stall=60)
            for _ in range(200):
                capture.feed(chunk)
    finally:
        reader.join(timeout=120)
        os.close(read_end)
    assert capture.console_error is None
    assert bytes(received) == chunk * 200


def test_a_full_console_is_given_up_and_says_why() -> None:
    with open("/dev/full", "wb", buffering=0) as full:
        capture = OutputCapture(full)
        capture.feed(b"first\n")
        capture.feed(b"second\n")
    assert capture.console_error is not None
    assert NO_SPACE in capture.console_error
    assert capture.tail_bytes() == b"first\nsecond\n"
