"""The output file gets every byte or says where it stopped; runner lines start their own line.

A full disk must never cut ``--output-file`` silently: an unbuffered write may take
fewer bytes than given without raising, so the capture writes the rest again, and when
the file takes no more it stops writing it, says how many bytes reached it and why
(``file_error``), and the console keeps getting everything. Runner lines after a test
line with no newline start on a line of their own, in every stream, while the tail kept
for the result file holds the test's bytes only.
"""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI
from helpers.tiny_disk import run_on_tiny_disk
from lxml import etree

from ros_isolated_test.process.capture import PREFIX, OutputCapture
from ros_isolated_test.xunit import validate

NO_SPACE = "No space left on device"


def result_root(path: Path) -> etree._Element:
    """The parsed result file, failing the test unless it matches schemas/junit.xsd."""
    assert path.is_file(), f"no result file at {path}"
    root = etree.parse(str(path), etree.XMLParser(resolve_entities=False)).getroot()
    assert validate.problems(root) == [], f"{path} does not match schemas/junit.xsd"
    return root


def runner_lines_removed(console: bytes) -> bytes:
    """The console without the runner's lines (and the newline put before each)."""
    return re.sub(rb"\n?" + re.escape(PREFIX.encode()) + rb"[^\n]*\n", b"", console)


# --- runner lines never glued to the test's last line ---------------------------------------


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


@pytest.mark.parametrize("mode", ["shell", "runner"])
def test_the_final_note_after_an_unterminated_last_line_is_on_a_line_of_its_own(
    mode: str, runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    log = tmp_path / "out.log"
    command = ["sh", "-c", "printf 'no newline'; exit 1"]
    if mode == "shell":
        argv = [CLI, "run", "--junit-xml", str(result), "--output-file", str(log), "--", *command]
    else:
        argv = [sys.executable, "-u", runner_script, str(result), "--output-file", str(log)]
        argv += ["--command", *command]
    done = subprocess.run(
        argv, env=env, cwd=tmp_path, capture_output=True, timeout=120, check=False
    )
    assert done.returncode == 1, done.stdout + done.stderr
    final = f"no newline\n{PREFIX}the test exited with code 1\n".encode()
    assert final in done.stdout
    assert final in log.read_bytes()
    error = result_root(result).find("testsuite/testcase/failure")
    assert error is not None
    assert (error.text or "").endswith("\n\nno newline"), "nothing added to the test's bytes"


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


# --- a file system that fills up for real ----------------------------------------------------

_FEED = textwrap.dedent(
    """
    import io, sys
    from pathlib import Path
    from ros_isolated_test.process.capture import OutputCapture

    log, out = Path(sys.argv[1]), Path(sys.argv[2])
    console = io.BytesIO()
    # As the session opens it: unbuffered, so a write may take only part of a chunk.
    with open(log, "wb", buffering=0) as handle:
        capture = OutputCapture(console, handle, tail_bytes=1 << 20)
        # 10000-byte chunks on a 64 KiB disk: the seventh is taken only in part, and
        # nothing is written after it, so only its own retry can notice.
        for index in range(6):
            capture.feed(bytes([65 + index]) * 9999 + b"\\n")
        capture.feed(b"z" * 10000)
        (out / "file").write_bytes(log.read_bytes())
    (out / "console").write_bytes(console.getvalue())
    (out / "error").write_text(str(capture.file_error))
    (out / "tail").write_bytes(capture.tail_bytes())
    """
)


@capabilities.MOUNT_NAMESPACE
def test_a_short_write_on_a_full_disk_is_written_again_and_its_error_reported(
    env: dict[str, str], tmp_path: Path
) -> None:
    disk = tmp_path / "disk"
    out = tmp_path / "out"
    out.mkdir()
    argv = [sys.executable, "-c", _FEED, str(disk / "out.log"), str(out)]
    done = run_on_tiny_disk(disk, argv, env, size="64k")
    assert done.returncode == 0, done.stderr.decode()
    fed = b"".join(bytes([65 + i]) * 9999 + b"\n" for i in range(6)) + b"z" * 10000
    written = (out / "file").read_bytes()
    error = (out / "error").read_text()
    assert 0 < len(written) < len(fed)
    assert written == fed[: len(written)], "the file holds a prefix of the output, nothing glued"
    assert NO_SPACE in error, error
    assert f"after {len(written)} bytes" in error
    note = f"{PREFIX}{error}; the output continues on the console only\n".encode()
    assert (out / "console").read_bytes() == fed + b"\n" + note
    assert (out / "tail").read_bytes() == fed


@capabilities.MOUNT_NAMESPACE
def test_a_full_disk_under_the_output_file_fails_the_run_and_says_so(
    env: dict[str, str], tmp_path: Path
) -> None:
    """End to end; the exit code and the result file need the session to report file_error."""
    disk = tmp_path / "disk"
    log = disk / "out.log"
    kept = tmp_path / "kept.log"
    result = tmp_path / "t.xml"
    script = "head -c 100000 /dev/zero | tr '\\0' x; printf END"
    argv = [CLI, "run", "--junit-xml", str(result), "--output-file", str(log), "--"]
    argv += ["sh", "-c", script]

    done = run_on_tiny_disk(disk, argv, env, size="64k", then=f"cp {log} {kept}")

    console = done.stdout
    written = kept.read_bytes()
    assert 0 < len(written) < len(console)
    assert console.startswith(written), "the file holds a prefix of the output, nothing glued"
    test_part = console.split(b"\n", 3)[3]  # after the runner's first three lines
    assert runner_lines_removed(test_part) == b"x" * 100000 + b"END", "console got everything"
    notes = [line for line in console.decode().splitlines() if NO_SPACE in line]
    assert len(notes) == 1, console[-2000:]
    assert notes[0].startswith(PREFIX), "the note is on a line of its own"
    assert f"after {len(written)} bytes" in notes[0]
    assert str(log) in notes[0]
    # Needs session: file_error makes the run fail and is named in the result file.
    assert done.returncode == 1, done.stderr.decode()
    assert NO_SPACE in result.read_text()
    result_root(result)


@capabilities.MOUNT_NAMESPACE
def test_control_the_same_run_with_room_writes_the_whole_output_file(
    env: dict[str, str], tmp_path: Path
) -> None:
    disk = tmp_path / "disk"
    log = disk / "out.log"
    kept = tmp_path / "kept.log"
    script = "head -c 10000 /dev/zero | tr '\\0' x; printf END"
    argv = [CLI, "run", "--output-file", str(log), "--", "sh", "-c", script]

    done = run_on_tiny_disk(disk, argv, env, size="64k", then=f"cp {log} {kept}")

    assert done.returncode == 0, done.stderr.decode()
    assert kept.read_bytes() == done.stdout
    assert NO_SPACE.encode() not in done.stdout


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


# --- runner lines with bytes that are not UTF-8 ----------------------------------------------


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
