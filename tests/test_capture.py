"""Output capture: live by chunks, any bytes, bounded memory, and results XML can carry."""

from __future__ import annotations

import io
import os
import re
import selectors
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import peak_rss
from helpers.commands import CLI
from helpers.results import load_result
from lxml import etree

from ros_isolated_test.process.capture import PREFIX, OutputCapture
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
