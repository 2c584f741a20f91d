"""A file system that fills up for real under the output file: every byte, or where it stopped.

A full disk must never cut ``--output-file`` silently: an unbuffered write may take
fewer bytes than given without raising, so the capture writes the rest again, and when
the file takes no more it stops writing it, says how many bytes reached it and why
(``file_error``), and the console keeps getting everything. Through the CLI the run
then fails and the result file says so. A 64 KiB tmpfs in a private mount namespace;
the control is the same run with room.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from helpers import capabilities
from helpers.commands import CLI
from helpers.output_capture import NO_SPACE, result_root, runner_lines_removed
from helpers.tiny_disk import run_on_tiny_disk

from ros_isolated_test.process.capture import PREFIX

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


def _run_onto_a_tiny_disk(
    tmp_path: Path, env: dict[str, str], size: int, *options: str
) -> tuple[subprocess.CompletedProcess[bytes], Path, bytes]:
    """``run OPTIONS --output-file`` on a 64 KiB disk, the test printing SIZE x's and END.

    Returns what the runner returned, the output file's path and the bytes it held.
    """
    disk = tmp_path / "disk"
    log = disk / "out.log"
    kept = tmp_path / "kept.log"
    script = f"head -c {size} /dev/zero | tr '\\0' x; printf END"
    argv = [CLI, "run", *options, "--output-file", str(log), "--", "sh", "-c", script]
    done = run_on_tiny_disk(disk, argv, env, size="64k", then=f"cp {log} {kept}")
    return done, log, kept.read_bytes()


@capabilities.MOUNT_NAMESPACE
def test_a_full_disk_under_the_output_file_fails_the_run_and_says_so(
    env: dict[str, str], tmp_path: Path
) -> None:
    """End to end; the exit code and the result file need the session to report file_error."""
    result = tmp_path / "t.xml"

    done, log, written = _run_onto_a_tiny_disk(tmp_path, env, 100000, "--junit-xml", str(result))

    console = done.stdout
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
    done, _log, written = _run_onto_a_tiny_disk(tmp_path, env, 10000)

    assert done.returncode == 0, done.stderr.decode()
    assert written == done.stdout
    assert NO_SPACE.encode() not in done.stdout
