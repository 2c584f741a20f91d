"""Orchestration promises: DISABLE_ROS_ISOLATION wherever the test's environment gets it,
and an --output-file that lost output (a full disk) failing a test that otherwise passed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, HUNG, ament, run_cli, run_runner
from helpers.domains import free_ids
from helpers.processes import stat_of
from helpers.results import load_result
from helpers.tiny_disk import fill, run_on_tiny_disk

WARNING = "WARNING: DISABLE_ROS_ISOLATION is set"
#: Writes the domain the test saw, so a test can tell it ran and where.
SEEN = ("sh", "-c", 'echo "${ROS_DOMAIN_ID-unset}" > seen')


# --- A.6: DISABLE_ROS_ISOLATION through --env (ament_add_test's ENV) ------------------------


@pytest.mark.parametrize(
    ("how", "runs"),
    [
        ("--env", True),  # ament_add_test(... ENV DISABLE_ROS_ISOLATION=1)
        ("environment", True),  # the runner's own environment
        ("neither", False),  # control: a preset ID is refused
        ("--env says no", False),  # the assignment has the last word over the environment
    ],
)
def test_disable_ros_isolation_counts_wherever_the_tests_environment_gets_it(
    env: dict[str, str], runner_script: str, tmp_path: Path, how: str, runs: bool
) -> None:
    options = ["--env", "ROS_DOMAIN_ID=42"]
    if how == "--env":
        options += ["--env", "DISABLE_ROS_ISOLATION=1"]
    elif how == "environment":
        env["DISABLE_ROS_ISOLATION"] = "1"
    elif how == "--env says no":
        env["DISABLE_ROS_ISOLATION"] = "1"
        options += ["--env", "DISABLE_ROS_ISOLATION=0"]
    result = tmp_path / "pkg" / "t.xml"
    options.append("--generate-result-on-success")
    proc = ament(runner_script, result, SEEN, env, *options, cwd=tmp_path)
    summary = load_result(result)
    if not runs:
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert not (tmp_path / "seen").exists()
        assert "DISABLE_ROS_ISOLATION=1" in proc.stderr
        assert summary.only.outcome in ("error", "failure")
        return
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "seen").read_text().strip() == "42"
    assert WARNING in proc.stdout  # loudly, as the environment variable does
    if how == "--env":
        assert "(by --env" in proc.stdout
    assert summary.properties.get("isolation") == "disabled"
    assert summary.only.outcome == "passed"


# --- A.8: a full disk under --output-file ---------------------------------------------------


@capabilities.MOUNT_NAMESPACE
@pytest.mark.parametrize(("exit_code", "expected"), [(0, 1), (5, 5)])
def test_an_output_file_that_lost_output_fails_a_passing_test_and_says_so(
    env: dict[str, str], tmp_path: Path, exit_code: int, expected: int
) -> None:
    disk = tmp_path / "disk"
    result = tmp_path / "r.xml"
    # The test fills the disk, then prints more than the output file's last page holds.
    script = (
        f"{fill(disk)}; head -c 20000 /dev/zero | tr '\\0' x; echo; "
        f"echo after-the-disk-filled; exit {exit_code}"
    )
    argv = [
        CLI,
        "run",
        "--junit-xml",
        str(result),
        "--output-file",
        str(disk / "out.log"),
        "--",
        "sh",
        "-c",
        script,
    ]
    done = run_on_tiny_disk(disk, argv, env)
    said = done.stdout.decode(errors="replace")
    assert done.returncode == expected, said + done.stderr.decode(errors="replace")
    assert "after-the-disk-filled" in said  # the console lost nothing
    summary = load_result(result)
    assert "failed" in summary.properties["output_file_error"]
    failed = [case for case in summary.cases if case.outcome in ("error", "failure")]
    assert failed, summary.cases
    text = " ".join(case.message + case.text for case in failed)
    if exit_code == 0:
        assert "output file" in text
    root_text = result.read_text()
    assert "after-the-disk-filled" in root_text  # the output tail is in the result


def test_an_output_file_with_room_passes(env: dict[str, str], tmp_path: Path) -> None:
    """Control: the same run with a disk that has room passes, with no such property."""
    result = tmp_path / "r.xml"
    out = tmp_path / "out.log"
    proc = run_cli(
        [
            "run",
            "--junit-xml",
            str(result),
            "--output-file",
            str(out),
            "--",
            "sh",
            "-c",
            "echo after",
        ],
        env,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = load_result(result)
    assert "output_file_error" not in summary.properties
    assert summary.only.outcome == "passed"
    assert "after" in out.read_text()


# --- bytes that are not UTF-8 in the command, an --env value, the working directory ----------

LATIN1 = b"caf\xe9"


def _bytes_run(
    argv: list[bytes], env: dict[str, str], cwd: Path
) -> subprocess.CompletedProcess[bytes]:
    """A runner process with bytes arguments; its output as bytes (the test echoes Latin-1)."""
    return subprocess.run(argv, env=env, cwd=cwd, capture_output=True, timeout=HUNG, check=False)


@pytest.mark.parametrize("where", ["argument", "--env", "cwd", "shell argument", "shell cwd"])
def test_bytes_that_are_not_utf8_reach_the_test_and_its_result_shows_them(
    env: dict[str, str], runner_script: str, tmp_path: Path, where: str
) -> None:
    """Python carries them as lone surrogates: the runner's lines and result show ``\\xe9``."""
    result = tmp_path / "t.xml"
    cwd = tmp_path
    # Writes what it got: its argument, $BAD, its working directory.
    test = [b"sh", b"-c", b'printf "%s|%s|%s" "$1" "$BAD" "$PWD" > "$0/seen"', bytes(tmp_path)]
    test.append(LATIN1 if where.endswith("argument") else b"-")
    options: list[bytes] = []
    if where == "--env":
        options = [b"--env", b"BAD=" + LATIN1]
    elif where.endswith("cwd"):
        cwd = Path(os.fsdecode(bytes(tmp_path) + b"/dir-" + LATIN1))
        cwd.mkdir()
    if where.startswith("shell"):
        argv = [os.fsencode(CLI), b"run", b"--junit-xml", bytes(result), b"--", *test]
    else:
        argv = [os.fsencode(sys.executable), b"-u", os.fsencode(runner_script), bytes(result)]
        argv += [b"--package-name", b"pkg", b"--generate-result-on-success", *options]
        argv += [b"--command", *test]

    done = _bytes_run(argv, env, cwd)

    assert done.returncode == 0, done.stdout + done.stderr
    assert b"Traceback" not in done.stderr
    assert LATIN1 in (tmp_path / "seen").read_bytes(), "the test got the bytes as they were"
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert "not generate" not in result.read_text(), "the placeholder was left"
    if where == "--env":
        shown = b" - BAD=caf\\xe9\n"
    elif where.endswith("cwd"):
        shown = b"/dir-caf\\xe9': "
    else:
        shown = b" 'caf\\xe9'\n"  # quoted as shlex quotes any non-ASCII word
        assert summary.properties["command"].endswith(" 'caf\\xe9'")
    assert shown in done.stdout, "shown in the runner's lines, never raw"
    assert LATIN1 not in done.stdout


def test_control_utf8_arguments_are_shown_as_they_are(
    env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    result = tmp_path / "t.xml"
    argv = [os.fsencode(sys.executable), b"-u", os.fsencode(runner_script), bytes(result)]
    argv += [b"--generate-result-on-success", b"--command", b"echo", "café".encode()]
    done = _bytes_run(argv, env, tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "café" in load_result(result).properties["command"]
    assert "echo 'café'\n".encode() in done.stdout


# --- a signal after the test ended, while its result is being written -----------------------

#: Writes a result file of ``$2`` passing cases at ``$1``: big enough that normalising it
#: takes a while, so a signal can arrive in the middle.
BIG_RESULT = """
import sys
count = int(sys.argv[2])
with open(sys.argv[1], "w") as out:
    out.write('<?xml version="1.0"?>\\n<testsuite name="big" tests="%d">\\n' % count)
    for index in range(count):
        out.write('<testcase classname="c" name="t%d" time="0.001"/>\\n' % index)
    out.write("</testsuite>\\n")
"""


def _signalled_while_concluding(
    runner_script: str, env: dict[str, str], tmp_path: Path, signum: int
) -> tuple[subprocess.Popen[bytes], Path]:
    """A runner whose test wrote a big result, signalled once it starts adopting that file."""
    result = tmp_path / "pkg" / "big.xml"
    original = result.with_name(result.name + ".orig")
    script = tmp_path / "big.py"
    script.write_text(BIG_RESULT)
    argv = [sys.executable, "-u", runner_script, str(result), "--package-name", "pkg"]
    argv += ["--command", sys.executable, str(script), str(result), "100000"]
    runner = subprocess.Popen(
        argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=tmp_path
    )
    try:
        while not os.path.lexists(original):
            assert runner.poll() is None, "the runner ended before it adopted the result"
            time.sleep(0.001)
        os.kill(runner.pid, signum)
        runner.wait(timeout=HUNG)
    finally:
        if runner.poll() is None:
            runner.kill()
            runner.wait()
    return runner, result


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_a_signal_while_the_result_is_written_is_noted_and_the_result_is_kept(
    runner_script: str, env: dict[str, str], tmp_path: Path, signum: int
) -> None:
    runner, result = _signalled_while_concluding(runner_script, env, tmp_path, signum)
    assert runner.stderr is not None
    stderr = runner.stderr.read().decode(errors="replace")
    assert runner.returncode == 0, stderr  # the test passed: the run's outcome stands
    assert "Traceback" not in stderr
    summary = load_result(result)
    assert summary.properties["signal_after_test"] == signal.Signals(signum).name
    assert len(summary.cases) == 100_000
    assert all(case.outcome == "passed" for case in summary.cases)
    assert result.with_name("big.xml.orig").is_file()


def test_control_without_a_signal_the_result_notes_none(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "big.xml"
    script = tmp_path / "big.py"
    script.write_text(BIG_RESULT)
    command = [sys.executable, str(script), str(result), "100"]
    proc = ament(runner_script, result, command, env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = load_result(result)
    assert "signal_after_test" not in summary.properties
    assert len(summary.cases) == 100


# --- --output-file naming a FIFO -------------------------------------------------------------


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
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=HUNG, check=False)
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
#: writes that to $3, then everything read.
FIFO_READER = """
import os, signal, sys, time
fifo_path, result, out_path, pid_path = sys.argv[1:5]
with open(fifo_path, "rb") as fifo:
    while not os.path.exists(pid_path):
        time.sleep(0.001)
    pid = int(open(pid_path).read())
    os.kill(pid, signal.SIGSTOP)
    while open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "T":
        time.sleep(0.001)
    before = os.path.exists(result)
    os.kill(pid, signal.SIGCONT)
    data = fifo.read()
with open(out_path, "wb") as out:
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
    argv += ["--generate-result-on-success", "--command", "echo", "through-the-fifo"]
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


# --- a console that is non-blocking, full, or gone -------------------------------------------


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


# --- what blocks an ID: the survivors the result names, never a process of an embedder -------

#: A program embedding the runner, with a child of its own running throughout: two runs
#: in a row on a pool of one ID, then what a fresh scan of its process tree finds.
EMBEDDER = """
import subprocess, sys
from pathlib import Path
from ros_isolated_test.process import supervisor
from ros_isolated_test.runner import session, settings
from ros_isolated_test.runner.request import Mode, RunRequest

own = subprocess.Popen(["sleep", "600"])
try:
    codes = []
    for name in ("first.xml", "second.xml"):
        request = RunRequest(
            ("true",), Mode.SHELL, settings.read(), result_file=Path(name),
            generate_result_on_success=True,
        )
        codes.append(session.run(request))
    scanned = [process.pid for process in supervisor.survivors()]
finally:
    own.kill()
    own.wait()
print("codes", *codes)
print("own", own.pid, "scanned", *scanned)
"""


def test_an_embedding_programs_own_child_never_blocks_the_id(
    env: dict[str, str], tmp_path: Path
) -> None:
    (domain_id,) = free_ids(1)
    env.update(ROS_ISOLATED_TEST_DOMAINS=str(domain_id), ROS_ISOLATED_TEST_WAIT_TIMEOUT="0")
    done = subprocess.run(
        [sys.executable, "-c", EMBEDDER],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=HUNG,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    own, scanned = lines[-1].split(" scanned")
    # The control: a fresh scan of the runner's tree does find the embedder's child.
    assert own.split()[1] in scanned.split(), done.stdout
    assert lines[-2] == "codes 0 0", done.stdout + done.stderr  # the second run got the ID
    assert "stays blocked" not in done.stdout
    assert "surviving_processes" not in load_result(tmp_path / "first.xml").properties


@pytest.mark.parametrize("disabled", [False, True], ids=["isolated", "isolation-disabled"])
def test_survivors_keep_the_resources_held_with_the_id_and_say_so(
    lock_dir: Path, disabled: bool
) -> None:
    """A survivor of the work keeps the ID and the GPU: the note names both, status shows it."""
    from ros_isolated_test.domain_coordinator import holdings
    from ros_isolated_test.runner import environment, session, settings

    ids = free_ids(1)
    environ = {
        "ROS_ISOLATED_TEST_LOCK_DIR": str(lock_dir),
        "ROS_ISOLATED_TEST_DOMAINS": str(ids[0]),
        "ROS_ISOLATED_TEST_CAPACITY": "gpu=1",
        **({"DISABLE_ROS_ISOLATION": "1"} if disabled else {}),
    }
    config = settings.read(environ, resources="gpu=1")
    policy = environment.decide((), config, environ)
    survivor = subprocess.Popen(["sleep", "600"])
    notes: list[str] = []
    try:
        with session.isolation(policy, config, ["work"], notes.append) as held:
            assert held is not None and held.resources == {"gpu": 1}
            stat = stat_of(survivor.pid)
            held.survivors = [stat]
        what = "gpu=1 stays" if disabled else f"ROS_DOMAIN_ID {ids[0]} and gpu=1 stay"
        assert any(
            note.startswith(f"{what} blocked while {stat.describe()} live") for note in notes
        ), notes
        assert [hold.survivors for hold in holdings.holds(lock_dir)] == [(survivor.pid,)]
    finally:
        survivor.kill()
        survivor.wait()
    # The control: with the survivor gone, nothing is held.
    assert holdings.holds(lock_dir) == []
