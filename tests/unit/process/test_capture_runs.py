"""Output capture as a run shows it, through ``run`` and the ctest RUNNER alike.

Live by chunks: output without a newline reaches the console while the test still runs
(a test held until told to go, so only live streaming can show it). Any bytes: invalid
UTF-8 and ANSI codes reach the console as produced and leave a valid result file,
shown as escapes, never as U+FFFD. Bounded memory: 200 MB of output leave the runner's
peak memory and the result file small, the tail kept and the cut marked. The runner's
final note after a test's unterminated last line starts a line of its own, and adds
nothing to the test's bytes in the result file.
"""

from __future__ import annotations

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
from helpers.output_capture import result_root
from helpers.results import load_result

from ros_isolated_test.process.capture import PREFIX


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
