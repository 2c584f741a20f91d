"""``streams``: where a run's words go: the console, the --output-file, the one error line.

Each is a small fight with the operating system that the run's steps never need to
read: a descriptor closed at start (``>&-``) must not become the test's stdout or a
lock's; a FIFO nobody reads must be a one-line error, not a hang before any result file
says so, while one with a reader gets the output, opened only after the placeholder
(so ctest killing the runner then still leaves a result); a console left non-blocking
gets every line, and a full one is noted, never failing the run; an output file that is
the result file is refused. In process where the call itself is the promise, through
real ``run`` and RUNNER processes where the console is the caller's.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers.commands import CLI, HUNG, run_process, run_runner
from helpers.results import load_result

from ros_isolated_test.runner import streams

# --- descriptors closed at start --------------------------------------------------------------

#: Run with fd 1 closed (``>&-``): keeps the standard descriptors when argv[1] is "kept",
#: then opens argv[2] and says (on stderr) which descriptor it got and what fd 1 is now.
CLOSED_STDOUT = """
import os, sys
from ros_isolated_test.runner import streams
if sys.argv[1] == "kept":
    streams.keep_standard_descriptors()
    streams.console().write(b"to the console, which is /dev/null")
fd = os.open(sys.argv[2], os.O_WRONLY | os.O_CREAT, 0o644)
null, one = os.stat(os.devnull), os.fstat(1)
where = "devnull" if (one.st_dev, one.st_ino) == (null.st_dev, null.st_ino) else "other"
os.write(2, f"{fd} {where}".encode())
"""


@pytest.mark.parametrize("kept", [True, False], ids=["kept", "control-not-kept"])
def test_a_closed_stdout_never_hands_descriptor_1_to_the_next_file(
    tmp_path: Path, kept: bool
) -> None:
    """Else the next file opened (a lock, the result) would be the test's stdout."""
    opened = tmp_path / "opened"
    mode = "kept" if kept else "not kept"
    argv = ["sh", "-c", 'exec "$0" -c "$1" "$2" "$3" >&-']
    argv += [sys.executable, CLOSED_STDOUT, mode, str(opened)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=HUNG, check=False)
    assert done.returncode == 0, done.stderr
    fd, where = done.stderr.split()
    if kept:
        assert int(fd) > 2 and where == "devnull", done.stderr
    else:
        # The control: without it, the file opened next is descriptor 1.
        assert (int(fd), where) == (1, "other"), done.stderr


# --- the --output-file ------------------------------------------------------------------------


def test_an_output_file_that_is_the_result_file_is_one_line_and_a_distinct_one_is_none(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A symlink and its target, ``./x`` and ``x``: one would overwrite the other."""
    target = tmp_path / "result.xml"
    link = tmp_path / "link.xml"
    link.symlink_to(target)
    said = streams.same_file_message(link, target)
    assert said is not None and "\n" not in said
    assert f"--output-file {link} is the result file {target}" in said
    assert "give the output file another name" in said
    monkeypatch.chdir(tmp_path)
    assert streams.same_file_message(Path("./result.xml"), Path("result.xml")) is not None
    # The control: a distinct file, or no file on either side, clashes with nothing.
    assert streams.same_file_message(tmp_path / "out.log", target) is None
    assert streams.same_file_message(None, target) is None
    assert streams.same_file_message(link, None) is None


def test_an_output_fifo_without_a_reader_fails_at_once_and_with_one_it_gets_the_output(
    tmp_path: Path,
) -> None:
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    with pytest.raises(OSError) as failed:
        streams.open_output(fifo)
    assert failed.value.errno == errno.ENXIO
    said = streams.output_message(fifo, failed.value)
    assert said.startswith(f"cannot open output file {fifo}: it is a FIFO that nobody reads")
    assert "start its reader first" in said
    # The control: with a reader (this process), it opens, blocking again, and gets the bytes.
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        with streams.open_output(fifo) as output:
            assert output is not None
            assert os.get_blocking(output.fileno()), "a slow reader must slow, never lose"
            output.write(b"through the fifo\n")
        assert os.read(reader, 100) == b"through the fifo\n"
    finally:
        os.close(reader)


def test_an_output_file_that_cannot_be_opened_names_the_reason_and_the_fix(
    tmp_path: Path,
) -> None:
    with pytest.raises(OSError) as failed:
        streams.open_output(tmp_path)  # a directory
    said = streams.output_message(tmp_path, failed.value)
    assert said == (
        f"cannot open output file {tmp_path}: Is a directory; choose a writable file path"
    )
    # The control: a file in a folder not made yet is opened, its folder made; none is none.
    with streams.open_output(tmp_path / "new" / "out.log") as output:
        assert output is not None
    assert (tmp_path / "new" / "out.log").is_file()
    with streams.open_output(None) as nothing:
        assert nothing is None


# --- the error line, and the streams of each attempt ----------------------------------------


def test_the_error_line_is_one_line_on_stderr_after_what_the_console_holds(
    capsys: pytest.CaptureFixture[str],
) -> None:
    read_end, write_end = os.pipe()
    with open(read_end, "rb") as reader, open(write_end, "wb") as console:
        console.write(b"the test's last words")  # buffered: not in the pipe yet
        streams.error(console, "it went wrong")
        os.set_blocking(reader.fileno(), False)  # nothing flushed: BlockingIOError, no hang
        assert os.read(reader.fileno(), 100) == b"the test's last words"  # flushed first
    assert capsys.readouterr().err == "ros-isolated-test: error: it went wrong\n"


def test_a_failed_console_or_output_file_stays_failed_in_the_next_attempt(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A stalled console would stall every attempt again; a cut output file stays cut."""
    with open("/dev/full", "wb", buffering=0) as full:
        both = streams.Streams(full, full)
        try:
            both.capture.feed(b"attempt 1\n")
            console_error, file_error = both.capture.console_error, both.capture.file_error
            assert console_error is not None and "No space left on device" in console_error
            assert file_error is not None
            capfd.readouterr()
            second = both.next_attempt()
            assert (second.console_error, second.file_error) == (console_error, file_error)
            second.feed(b"attempt 2\n")
            assert second.file_bytes == 0
            assert capfd.readouterr().err == "", "the failed console was tried again"
        finally:
            both.close()
    # The control: a console and an output file that work get both attempts' output.
    console_path, output_path = tmp_path / "console", tmp_path / "output"
    with open(console_path, "wb", buffering=0) as console, open(output_path, "wb") as output:
        both = streams.Streams(console, output)
        both.capture.feed(b"attempt 1\n")
        both.next_attempt().feed(b"attempt 2\n")
        assert both.capture.console_error is None and both.capture.file_error is None
        both.close()
    assert console_path.read_bytes() == output_path.read_bytes() == b"attempt 1\nattempt 2\n"


# --- real runs: an output FIFO, and the console ----------------------------------------------


@pytest.mark.parametrize("mode", ["runner", "shell"])
def test_an_output_fifo_nobody_reads_is_a_one_line_error_and_nothing_runs(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """Opened blocking, it would hang the runner before any result file said so."""
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    result = tmp_path / "pkg" / "t.xml"
    ran = tmp_path / "ran"
    if mode == "runner":
        argv = [sys.executable, "-u", runner_script, str(result), "--output-file", str(fifo)]
        argv += ["--command", "touch", str(ran)]
    else:
        argv = [CLI, "run", "--junit-xml", str(result), "--output-file", str(fifo), "--"]
        argv += ["touch", str(ran)]
    done = run_process(argv, env)
    assert done.returncode == 2, done.stdout + done.stderr
    assert not ran.exists(), "the test ran"
    errors = done.stderr.splitlines()
    assert len(errors) == 1, done.stderr
    assert str(fifo) in errors[0]
    assert "FIFO" in errors[0]
    said = load_result(result).only
    assert said.outcome == "error"
    assert "FIFO" in said.message


#: Opens the FIFO ($1) for reading, which returns once the runner ($4 holds its PID) opens
#: it; stops the runner there, so whether the result file ($2) existed by then is certain;
#: writes that to $3, then everything read. The test writes more than a pipe holds, so the
#: runner cannot end before the reader reads, however late the reader is scheduled.
FIFO_READER = """
import os, signal, sys, time
fifo_path, result, out_path, pid_path = sys.argv[1:5]
with open(fifo_path, "rb") as fifo:
    while not os.path.exists(pid_path):
        time.sleep(0.001)
    pid = int(open(pid_path).read())
    os.kill(pid, signal.SIGSTOP)
    state = ""
    while state not in ("T", "Z"):
        time.sleep(0.001)
        state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    before = os.path.exists(result)
    os.kill(pid, signal.SIGCONT)
    data = fifo.read()
with open(out_path, "wb") as out:
    if state == "Z":
        out.write(b"the runner ended before it was stopped\\n")
    else:
        out.write(b"placeholder first\\n" if before else b"opened first\\n")
    out.write(data)
"""


def test_an_output_fifo_with_a_reader_is_opened_after_the_placeholder_and_gets_the_output(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """Control for the FIFO nobody reads; and ctest killing the runner now leaves a result."""
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    result = tmp_path / "pkg" / "t.xml"
    got = tmp_path / "got"
    pid_file = tmp_path / "runner.pid"
    reader_argv = [sys.executable, "-c", FIFO_READER, str(fifo), str(result), str(got)]
    reader = subprocess.Popen([*reader_argv, str(pid_file)])
    argv = [sys.executable, "-u", runner_script, str(result), "--output-file", str(fifo)]
    talk = "import sys; sys.stdout.write('through-the-fifo\\n' + 'x' * 300_000 + '\\n')"
    argv += ["--generate-result-on-success", "--command", sys.executable, "-c", talk]
    try:
        with subprocess.Popen(
            argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        ) as runner:
            (tmp_path / "pid.tmp").write_text(str(runner.pid))
            (tmp_path / "pid.tmp").rename(pid_file)
            stdout, stderr = runner.communicate(timeout=HUNG)
        assert reader.wait(timeout=HUNG) == 0
    finally:
        if reader.poll() is None:
            reader.kill()
            reader.wait()
    assert runner.returncode == 0, stdout + stderr
    said = got.read_bytes()
    assert said.startswith(b"placeholder first\n"), said
    assert b"through-the-fifo\n" in said
    assert load_result(result).only.outcome == "passed"


@pytest.mark.parametrize("mode", ["runner", "shell"])
def test_a_non_blocking_console_with_a_slow_reader_gets_every_line(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """Whoever shares the pipe set O_NONBLOCK on it: a write that would block waits for room."""
    result = tmp_path / "pkg" / "t.xml"
    lines = 2000
    command = [
        sys.executable,
        "-c",
        f"import os\nfor i in range({lines}): os.write(1, b'%05d ' % i + b'x' * 500 + b'\\n')",
    ]
    if mode == "runner":
        argv = [sys.executable, "-u", runner_script, str(result)]
        argv += ["--generate-result-on-success", "--command", *command]
    else:
        argv = [CLI, "run", "--junit-xml", str(result), "--", *command]
        env.pop("PYTHONUNBUFFERED", None)  # the CLI's own buffered stdout
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    try:
        runner = subprocess.Popen(argv, env=env, stdout=write_end, stderr=subprocess.PIPE)
    finally:
        os.close(write_end)
    with os.fdopen(read_end, "rb") as reader:
        # The slow reader: the pipe fills (64 KiB) long before the test is done.
        time.sleep(0.5)
        console = reader.read()
    assert runner.stderr is not None
    stderr = runner.stderr.read().decode(errors="replace")
    assert runner.wait(timeout=HUNG) == 0, stderr
    for index in range(lines):
        assert b"%05d " % index + b"x" * 500 + b"\n" in console, f"line {index} lost"
    assert "console_error" not in load_result(result).properties


@pytest.mark.parametrize("mode", ["runner", "shell"])
def test_a_full_console_is_noted_in_the_result_and_never_fails_the_run(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    if mode == "runner":
        argv = [sys.executable, "-u", runner_script, str(result)]
        argv += ["--generate-result-on-success", "--command", "echo", "hello"]
    else:
        argv = [CLI, "run", "--junit-xml", str(result), "--", "echo", "hello"]
        env.pop("PYTHONUNBUFFERED", None)  # a buffer would keep what /dev/full refused
    with open("/dev/full", "wb") as full:
        done = subprocess.run(
            argv,
            env=env,
            stdout=full,
            stderr=subprocess.PIPE,
            text=True,
            timeout=HUNG,
            check=False,
        )
    assert done.returncode == 0, done.stderr  # a console never fails the run
    assert "Traceback" not in done.stderr
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert "No space left on device" in summary.properties["console_error"]
    assert "No space left on device" in done.stderr  # stderr still works: said there


def test_control_a_console_that_works_is_not_noted(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    args = [str(result), "--generate-result-on-success", "--command", "echo", "hello"]
    done = run_runner(runner_script, args, env)
    assert done.returncode == 0, done.stderr
    assert "hello\n" in done.stdout
    assert "console_error" not in load_result(result).properties
