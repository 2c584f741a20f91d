"""Output capture: live by chunks, any bytes, bounded memory, every byte to the output file or
where it stopped, runner lines on lines of their own, and results XML can carry."""

from __future__ import annotations

import io
import os
import re
import selectors
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
from helpers import capabilities, peak_rss
from helpers.commands import CLI
from helpers.results import load_result
from helpers.tiny_disk import run_on_tiny_disk
from lxml import etree

from ros_isolated_test.process.capture import PREFIX, OutputCapture
from ros_isolated_test.xunit import validate
from ros_isolated_test.xunit.xml_text import xml_safe

# --- end to end ------------------------------------------------------------------------------


def _read_until(stream: int, marker: bytes, limit_seconds: float) -> bytes:
    """Bytes from ``stream`` until ``marker`` shows up; fails after ``limit_seconds``."""
    seen = b""
    deadline = time.monotonic() + limit_seconds
    with selectors.DefaultSelector() as selector:
        selector.register(stream, selectors.EVENT_READ)
        while marker not in seen:
            left = deadline - time.monotonic()
            if left <= 0 or not selector.select(left):
                pytest.fail(f"{marker!r} never arrived; got {seen!r}")
            chunk = os.read(stream, 65536)
            if not chunk:
                pytest.fail(f"output ended before {marker!r}; got {seen!r}")
            seen += chunk
    return seen


@pytest.mark.parametrize("mode", ["shell", "runner"])
def test_output_without_newline_arrives_while_the_test_still_runs(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """The test holds until it is told to go, so only live streaming can show ``partial``."""
    go = tmp_path / "go"
    command = [
        "sh",
        "-c",
        # Markers built at run time: the runner echoes the command line itself.
        "printf par%s tial; i=0;"
        ' while [ ! -e "$0" ] && [ $i -lt 600 ]; do sleep 0.05; i=$((i+1)); done;'
        " printf '\\nfin%s\\n' ished",
        str(go),
    ]
    if mode == "shell":
        argv = [CLI, "run", "--", *command]
    else:
        result = tmp_path / "pkg" / "t.xml"
        argv = [sys.executable, "-u", runner_script, str(result), "--generate-result-on-success"]
        argv += ["--command", *command]
    runner = subprocess.Popen(argv, env=env, cwd=tmp_path, stdout=subprocess.PIPE)
    assert runner.stdout is not None
    try:
        early = _read_until(runner.stdout.fileno(), b"partial", 20)
        assert runner.poll() is None, "the runner ended before the test was let go"
        assert b"finished" not in early
        go.touch()
        rest = runner.stdout.read()
        assert runner.wait(timeout=30) == 0
    finally:
        if runner.poll() is None:
            runner.kill()
            runner.wait()
        runner.stdout.close()
    assert b"partial\nfinished\n" in early + rest


@pytest.mark.parametrize("mode", ["shell", "runner"])
def test_invalid_utf8_and_ansi_codes_leave_a_valid_result(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    script = (
        r"printf 'bad \377\376 bytes\n\033[31mred\033[0m text\n"
        r"nul\000 bell\007 esc\033 end\n'; exit 1"
    )
    command = ["sh", "-c", script]
    if mode == "shell":
        argv = [CLI, "run", "--junit-xml", str(result), "--", *command]
    else:
        argv = [sys.executable, "-u", runner_script, str(result), "--command", *command]
    proc = subprocess.run(argv, env=env, cwd=tmp_path, capture_output=True, timeout=60, check=False)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    # The console gets the bytes as they were produced.
    assert b"bad \xff\xfe bytes\n\x1b[31mred\x1b[0m text\n" in proc.stdout
    case = load_result(result).only
    assert case.outcome == "failure"
    assert "red text" in case.text, "ANSI colour codes are stripped"
    assert "\x1b" not in case.text
    # Shown as \xNN, never U+FFFD: xunit-viewer aborts its whole run on a U+FFFD.
    assert "bad \\xff\\xfe bytes" in case.text
    assert "bell" in case.text
    assert "end" in case.text


def _peak_rss_kib(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[int, int]:
    """Run ``argv`` with output discarded; its exit code and peak RSS (KiB).

    The peak is the largest among the runner and the descendants it waited for; those
    are sh, head and tr here, all far smaller than a Python runner.
    """
    peak = peak_rss.measure(argv, env=env, cwd=cwd)
    assert not peak.timed_out
    return peak.returncode, peak.max_rss // 1024


def test_huge_output_keeps_memory_and_result_file_small(
    env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "r.xml"
    total = 200_000_000
    script = f"head -c {total} /dev/zero | tr '\\0' x; echo; echo THE-LAST-LINE; exit 1"
    code, peak_kib = _peak_rss_kib(
        [CLI, "run", "--junit-xml", str(result), "--", "sh", "-c", script], env, tmp_path
    )
    assert code == 1
    assert peak_kib < 100 * 1024, f"runner peak RSS {peak_kib} KiB for 200 MB of output"
    assert result.stat().st_size < 1_000_000
    case = load_result(result).only
    assert case.outcome == "failure"
    assert case.text.rstrip().endswith("THE-LAST-LINE"), "the tail is kept"
    match = re.search(r"\[\.\.\. (\d+) earlier bytes of output not kept here \.\.\.\]", case.text)
    assert match, "the cut is marked"
    assert int(match.group(1)) > total - 1_000_000


# --- OutputCapture ----------------------------------------------------------------------------


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


# --- xml_safe ---------------------------------------------------------------------------------


def _embeds(text: str) -> str:
    """Round-trip ``text`` through an lxml element and a parse, as a result file does."""
    element = etree.Element("failure", message=text)
    element.text = text
    parsed = etree.fromstring(etree.tostring(element))
    assert parsed.get("message") == text
    return parsed.text or ""


def test_xml_safe_drops_ansi_codes_and_shows_other_illegal_characters() -> None:
    raw = "\x1b[1;31mred\x1b[0m nul\x00 bell\x07 vt\x0b lone-esc\x1b| ff\x0c surrogate\ud800 ok"
    with pytest.raises(ValueError):
        _embeds(raw)
    safe = xml_safe(raw)
    assert safe == "red nul\\x00 bell\\x07 vt\\x0b lone-esc\\x1b| ff\\x0c surrogate\\ud800 ok"
    assert _embeds(safe) == safe


def test_xml_safe_keeps_legal_text_as_it_is() -> None:
    text = "tab\tnewline\nreturn\r <&>\"' ünïcode 漢字 \U0001f916 \u0085 \x7f"
    assert xml_safe(text) == text


def test_xml_safe_shows_the_replacement_character() -> None:
    """Legal XML, but xunit-viewer takes a file holding U+FFFD for CP1252 and aborts."""
    assert xml_safe("a\ufffdb") == "a\\ufffdb"


def test_xml_safe_caps_long_text_keeping_head_and_tail() -> None:
    text = "HEAD" + "m" * 992 + "TAIL"
    safe = xml_safe(text, limit=100)
    assert safe.startswith("HEAD" + "m" * 46 + "\n")
    assert safe.endswith("\n" + "m" * 46 + "TAIL")
    assert "\n[... 900 characters cut ...]\n" in safe
    assert len(safe) < 100 + len("\n[... 900 characters cut ...]\n") + 1


def test_xml_safe_cap_counts_characters_after_cleaning() -> None:
    text = "\x1b[31m" * 1000 + "short"
    assert xml_safe(text, limit=100) == "short"


def test_xml_safe_at_the_limit_is_not_cut() -> None:
    text = "x" * 100
    assert xml_safe(text, limit=100) == text


# --- the output file gets every byte or says where it stopped ----------------------------
#
# The output file gets every byte or says where it stopped; runner lines start their own line.
#
# A full disk must never cut ``--output-file`` silently: an unbuffered write may take
# fewer bytes than given without raising, so the capture writes the rest again, and when
# the file takes no more it stops writing it, says how many bytes reached it and why
# (``file_error``), and the console keeps getting everything. Runner lines after a test
# line with no newline start on a line of their own, in every stream, while the tail kept
# for the result file holds the test's bytes only.

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
