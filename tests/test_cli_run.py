"""``ros-isolated-test run -- CMD`` and the other commands, as real processes."""

from __future__ import annotations

import contextlib
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import BIN, CLI, MODES, run_cli, the_error_line, through
from helpers.results import load_result


def run(args: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return run_cli(["run", *args], env, cwd=cwd)


# --- exit codes ------------------------------------------------------------------------------


@pytest.mark.parametrize("code", [0, 3])
def test_exit_code_is_the_commands(env: dict[str, str], tmp_path: Path, code: int) -> None:
    proc = run(["--", "sh", "-c", f"exit {code}"], env, tmp_path)
    assert proc.returncode == code, proc.stdout + proc.stderr
    assert proc.stdout.startswith("Running with ROS_DOMAIN_ID ")


@pytest.mark.parametrize(
    ("sig", "expected"), [(signal.SIGSEGV, 139), (signal.SIGKILL, 137), (signal.SIGTERM, 143)]
)
def test_signal_death_gives_128_plus_n_and_the_result_names_it(
    env: dict[str, str], tmp_path: Path, sig: signal.Signals, expected: int
) -> None:
    result = tmp_path / "r.xml"
    proc = run(
        ["--junit-xml", str(result), "--", "sh", "-c", f"ulimit -c 0; kill -{sig.name[3:]} $$"],
        env,
        tmp_path,
    )
    assert proc.returncode == expected, proc.stdout + proc.stderr
    case = load_result(result).only
    assert case.outcome == "failure"
    assert f"killed by {sig.name} (signal {int(sig)})" in case.message


def test_command_not_found_gives_127(env: dict[str, str], tmp_path: Path) -> None:
    result = tmp_path / "r.xml"
    proc = run(["--junit-xml", str(result), "--", "no-such-command-rit"], env, tmp_path)
    assert proc.returncode == 127, proc.stdout + proc.stderr
    case = load_result(result).only
    assert case.outcome == "error"
    assert "no-such-command-rit" in case.message


def test_command_not_executable_gives_126(env: dict[str, str], tmp_path: Path) -> None:
    script = tmp_path / "script.sh"
    script.write_text("#!/bin/sh\ntouch ran\n")
    script.chmod(0o644)
    result = tmp_path / "r.xml"
    proc = run(["--junit-xml", str(result), "--", str(script)], env, tmp_path)
    assert proc.returncode == 126, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "Permission denied" in load_result(result).only.message


def test_timeout_stops_the_test_with_124(env: dict[str, str], tmp_path: Path) -> None:
    result = tmp_path / "r.xml"
    proc = subprocess.run(
        [CLI, "run", "--timeout", "1", "--junit-xml", str(result), "--", "sleep", "30"],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        check=False,
        text=True,
        timeout=20,
    )
    assert proc.returncode == 124, proc.stdout + proc.stderr
    case = load_result(result).only
    assert case.outcome == "failure"
    assert "timed out" in case.message
    assert "--timeout 1" in case.message


def test_timeout_kills_a_test_that_ignores_sigterm(env: dict[str, str], tmp_path: Path) -> None:
    stubborn = (
        "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
        "print('ignoring TERM', flush=True); time.sleep(30)"
    )
    proc = subprocess.run(
        [
            CLI,
            "run",
            "--timeout",
            "0.5",
            "--kill-grace",
            "0.5",
            "--",
            sys.executable,
            "-c",
            stubborn,
        ],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        check=False,
        text=True,
        timeout=20,
    )
    assert proc.returncode == 124, proc.stdout + proc.stderr
    assert "ignoring TERM" in proc.stdout


def test_timeout_still_applies_after_the_test_closed_its_output(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A test that closes stdout and stderr (a daemon-style node) must still be stopped."""
    result = tmp_path / "r.xml"
    quiet = "exec >/dev/null 2>&1; exec sleep 3"
    proc = subprocess.run(
        [CLI, "run", "--timeout", "1", "--junit-xml", str(result), "--", "sh", "-c", quiet],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        check=False,
        text=True,
        timeout=20,
    )
    assert proc.returncode == 124, proc.stdout + proc.stderr
    assert "timed out" in load_result(result).only.message


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def test_timeout_also_stops_the_tests_children(env: dict[str, str], tmp_path: Path) -> None:
    proc = run(
        [
            "--timeout",
            "1",
            "--kill-grace",
            "0.5",
            "--",
            "sh",
            "-c",
            "sleep 30 & echo $! > child.pid; wait",
        ],
        env,
        tmp_path,
    )
    child = int((tmp_path / "child.pid").read_text())
    try:
        assert proc.returncode == 124, proc.stdout + proc.stderr
        deadline = time.monotonic() + 2
        while _alive(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(child), "the test's child survived the timeout"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(child, signal.SIGKILL)


# --- files ---------------------------------------------------------------------------------


def test_output_file_gets_the_merged_output(env: dict[str, str], tmp_path: Path) -> None:
    log = tmp_path / "logs" / "out.log"
    proc = run(
        ["--output-file", str(log), "--", "sh", "-c", "echo to-out; echo to-err >&2"],
        env,
        tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "to-out\nto-err\n" in log.read_text()
    assert "to-out\nto-err\n" in proc.stdout


def test_junit_xml_on_success_writes_a_passed_case(env: dict[str, str], tmp_path: Path) -> None:
    result = tmp_path / "results" / "r.xml"
    proc = run(
        ["--junit-xml", str(result), "--package-name", "demo", "--", "echo", "hi"], env, tmp_path
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert summary.suites == ("demo.r",)
    assert summary.properties["command"] == "echo hi"


def test_junit_xml_on_failure_keeps_the_output(env: dict[str, str], tmp_path: Path) -> None:
    result = tmp_path / "r.xml"
    proc = run(
        ["--junit-xml", str(result), "--", "sh", "-c", "echo why-it-broke; exit 3"], env, tmp_path
    )
    assert proc.returncode == 3
    case = load_result(result).only
    assert case.outcome == "failure"
    assert "exited with code 3" in case.message
    assert "why-it-broke" in case.text


def test_runner_options_after_the_double_dash_go_to_the_command(
    env: dict[str, str], tmp_path: Path
) -> None:
    proc = run(
        ["--", "sh", "-c", 'echo "seen $*"', "sh", "--timeout", "1", "--help"], env, tmp_path
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen --timeout 1 --help\n" in proc.stdout


# --- usage and help --------------------------------------------------------------------------


@pytest.mark.parametrize("args", [["run"], ["run", "--"], ["run", "--junit-xml", "x.xml"]])
def test_missing_command_is_a_usage_error(
    env: dict[str, str], tmp_path: Path, args: list[str]
) -> None:
    proc = run_cli(args, env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Missing argument" in proc.stderr
    if "--junit-xml" in args:
        # Nothing ran, and the result file asked for says why.
        case = load_result(tmp_path / "x.xml").only
        assert case.outcome == "error"
        assert "Missing argument" in case.message
    else:
        assert not (tmp_path / "x.xml").exists()


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ["--help"],
            [
                "run",
                "runner-path",
                "status",
                "ROS_ISOLATED_TEST_DOMAINS",
                "ROS_ISOLATED_TEST_LOCK_DIR",
                "DISABLE_ROS_ISOLATION",
            ],
        ),
        (
            ["run", "--help"],
            [
                "--",
                "--junit-xml",
                "--timeout",
                "--output-file",
                "Exit codes",
                "128+N",
                "124",
                "126/127",
                "ROS_DOMAIN_ID",
                "DISABLE_ROS_ISOLATION=1",
            ],
        ),
        (["runner-path", "--help"], ["RUNNER", "ament_add_test", "add_launch_test"]),
        (["status", "--help"], ["--json", "32768"]),
    ],
    ids=["top", "run", "runner-path", "status"],
)
def test_help_of_every_command(
    env: dict[str, str], tmp_path: Path, args: list[str], expected: list[str]
) -> None:
    proc = run_cli(args, env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Usage:" in proc.stdout
    for text in expected:
        assert text in proc.stdout, f"{text!r} missing from `{' '.join(args)}`"


def test_runner_path_prints_an_existing_absolute_python_file(
    env: dict[str, str], tmp_path: Path
) -> None:
    proc = run_cli(["runner-path"], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    path = Path(proc.stdout.strip())
    assert proc.stdout == f"{path}\n"
    assert path.is_absolute()
    assert path.suffix == ".py"
    assert path.is_file()


# --- the RUNNER script with a Python that lacks the package --------------------------------


@capabilities.BARE_PYTHON
def test_runner_script_reexecs_with_the_clis_python(
    runner_script: str, lock_dir: Path, tmp_path: Path
) -> None:
    python = capabilities.bare_python()
    assert python is not None
    result = tmp_path / "pkg" / "t.xml"
    # The runner's own command line, read by the test: it must be the venv's interpreter.
    command = ["sh", "-c", "tr '\\0' ' ' < /proc/$PPID/cmdline; echo"]
    proc = subprocess.run(
        [
            "/usr/bin/env",
            "-i",
            f"PATH={BIN}:/usr/bin:/bin",
            f"ROS_ISOLATED_TEST_LOCK_DIR={lock_dir}",
            python,
            "-u",
            runner_script,
            str(result),
            "--package-name",
            "pkg",
            "--generate-result-on-success",
            "--command",
            *command,
        ],
        capture_output=True,
        check=False,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.startswith("Running with ROS_DOMAIN_ID ")
    assert f"{BIN}/python" in proc.stdout
    assert load_result(result).only.outcome == "passed"


@capabilities.BARE_PYTHON
def test_runner_script_without_the_cli_on_path_says_how_to_fix_it(
    runner_script: str, lock_dir: Path, tmp_path: Path
) -> None:
    python = capabilities.bare_python()
    assert python is not None
    proc = subprocess.run(
        [
            "/usr/bin/env",
            "-i",
            "PATH=/usr/bin:/bin",
            f"ROS_ISOLATED_TEST_LOCK_DIR={lock_dir}",
            python,
            "-u",
            runner_script,
            str(tmp_path / "t.xml"),
            "--command",
            "touch",
            "ran",
        ],
        capture_output=True,
        check=False,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert proc.returncode == 2
    assert not (tmp_path / "ran").exists()
    assert "cannot import ros-isolated-test" in proc.stderr
    assert "Python3_EXECUTABLE" in proc.stderr


# --- signals to the runner -----------------------------------------------------------------


TRAPS_TERM = """
import pathlib, signal, sys, time
def on_term(signum, frame):
    pathlib.Path('got-term').write_text(str(signum))
    sys.exit(0)
signal.signal(signal.SIGTERM, on_term)
print('ready', flush=True)
time.sleep(30)
sys.exit(9)
"""


def _start_and_terminate(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[int, str]:
    """Start a runner, wait for its test's ``ready``, SIGTERM the runner; its code and output."""
    runner = subprocess.Popen(argv, env=env, cwd=cwd, stdout=subprocess.PIPE, text=True)
    assert runner.stdout is not None
    try:
        seen = []
        for line in runner.stdout:
            seen.append(line)
            if line == "ready\n":
                break
        else:
            pytest.fail(f"the test never became ready:\n{''.join(seen)}")
        runner.send_signal(signal.SIGTERM)
        rest, _ = runner.communicate(timeout=30)
    finally:
        if runner.poll() is None:
            runner.kill()
            runner.wait()
    return runner.returncode, "".join(seen) + rest


@pytest.mark.parametrize("mode", ["shell", "runner"])
def test_sigterm_to_the_runner_is_passed_on_to_the_test(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """SIGTERM (ctest, a container stop) is passed on to the test.

    Even when the test handles it and exits 0, the run was interrupted, not passed: the
    runner exits 128+15 and the result names the signal.
    """
    result = tmp_path / "pkg" / "t.xml"
    command = [sys.executable, "-c", TRAPS_TERM]
    if mode == "shell":
        argv = [CLI, "run", "--junit-xml", str(result), "--", *command]
    else:
        argv = [
            sys.executable,
            "-u",
            runner_script,
            str(result),
            "--package-name",
            "pkg",
            "--generate-result-on-success",
            "--command",
            *command,
        ]
    code, output = _start_and_terminate(argv, env, tmp_path)
    assert (tmp_path / "got-term").read_text() == str(int(signal.SIGTERM))
    assert code == 128 + signal.SIGTERM, output
    case = load_result(result).only
    assert case.outcome == "failure"
    assert "was interrupted: the runner received SIGTERM" in case.message
    assert "exited with code 0" in case.message


def test_test_killed_by_forwarded_sigterm_is_reported(env: dict[str, str], tmp_path: Path) -> None:
    result = tmp_path / "r.xml"
    quiet_sleeper = "import time; print('ready', flush=True); time.sleep(30)"
    argv = [CLI, "run", "--junit-xml", str(result), "--", sys.executable, "-c", quiet_sleeper]
    code, output = _start_and_terminate(argv, env, tmp_path)
    assert code == 128 + signal.SIGTERM, output
    case = load_result(result).only
    assert case.outcome == "failure"
    assert "the runner received SIGTERM, passed it on" in case.message
    assert "was killed by SIGTERM" in case.message


def test_status_lists_nothing_in_a_fresh_lock_dir(env: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(["status", "--json"], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert '"via": "lock"' not in proc.stdout
    assert os.listdir(env["ROS_ISOLATED_TEST_LOCK_DIR"]) == []


# --- result paths that are not regular files ---------------------------------------------------
#
# A rename replaces whatever is at the path: as root, `--junit-xml /dev/null` once replaced
# the machine's /dev/null. The null device discards the result; any other device node, FIFO
# or socket (or a symlink to one) is refused before anything runs.


def _special_at(kind: str, folder: Path) -> Path:
    """A FIFO at ``folder/r.xml``, or a symlink there to one."""
    fifo = folder / ("r.xml" if kind == "fifo" else "fifo")
    os.mkfifo(fifo)
    if kind == "fifo":
        return fifo
    link = folder / "r.xml"
    link.symlink_to(fifo)
    return link


@pytest.mark.parametrize("kind", ["fifo", "symlink to a fifo"])
@pytest.mark.parametrize("mode", MODES)
def test_a_fifo_result_path_is_refused_before_anything_runs(
    runner_script: str, env: dict[str, str], lock_dir: Path, tmp_path: Path, mode: str, kind: str
) -> None:
    result = _special_at(kind, tmp_path)
    before = os.lstat(result)
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], result)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    line = the_error_line(proc)
    said = "a symlink to a FIFO" if kind.startswith("symlink") else "a FIFO"
    assert str(result) in line and f"it is {said}" in line, line
    assert "name a regular file" in line, line
    assert not (tmp_path / "ran").exists(), "the test ran"
    assert list(lock_dir.iterdir()) == [], "something was reserved"
    after = os.lstat(result)
    assert (after.st_ino, after.st_mode) == (before.st_ino, before.st_mode)


@pytest.mark.parametrize("mode", MODES)
def test_control_a_regular_result_path_is_replaced_atomically(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    result = tmp_path / "pkg" / "r.xml"
    result.parent.mkdir()
    result.write_text("a stale result of an earlier run\n")
    before = os.lstat(result)
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], result)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    assert os.lstat(result).st_ino != before.st_ino
    assert load_result(result).only.outcome == "passed"


@pytest.mark.parametrize("mode", MODES)
def test_a_symlink_to_dev_null_as_the_result_path_discards_the_result(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """As ``pytest --junit-xml=/dev/null``: the test runs, nothing is written, the link stays."""
    link = tmp_path / "r.xml"
    link.symlink_to(os.devnull)
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], link)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    assert link.is_symlink() and os.readlink(link) == os.devnull
    assert sorted(item.name for item in tmp_path.iterdir()) == ["r.xml", "ran"]


@capabilities.ROOT
@pytest.mark.parametrize("mode", MODES)
def test_a_null_device_node_as_the_result_path_is_kept_and_the_output_file_still_works(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    """The issue's reproduction: ``mknod $D/null c 1 3; run --junit-xml $D/null -- true``.

    The output goes to a second such node, as --output-file to a device always could.
    """
    null, output = tmp_path / "null", tmp_path / "output"
    for node in (null, output):
        os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    if mode == "shell":
        args = ["--junit-xml", str(null), "--output-file", str(output), "--", "touch", "ran"]
        proc = run(args, env, tmp_path)
    else:
        options = ["--output-file", str(output)]
        proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"], null, options)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    for node in (null, output):
        found = os.lstat(node)
        assert stat.S_ISCHR(found.st_mode) and found.st_rdev == os.makedev(1, 3), node
    assert sorted(item.name for item in tmp_path.iterdir()) == ["null", "output", "ran"]


@pytest.mark.parametrize("left", ["fifo", "regular file"])
def test_a_fifo_the_test_leaves_at_the_result_path_is_not_replaced_at_write_time(
    runner_script: str, env: dict[str, str], tmp_path: Path, left: str
) -> None:
    """Checked again when the result is written: the path became a FIFO while the test ran.

    --generate-result-on-success writes over the test's own file (run_test.py's rule), so
    nothing is kept aside: the FIFO stays, and the run fails saying why. The control: a
    regular file the test leaves there is replaced by the passed result.
    """
    result = tmp_path / "pkg" / "r.xml"
    make = 'mkfifo "$1"' if left == "fifo" else 'echo left > "$1"'
    command = ["sh", "-c", f'rm -f "$1"; {make}', "t", str(result)]
    proc = through("runner", runner_script, env, tmp_path, command, result)
    if left == "fifo":
        assert proc.returncode == 1, proc.stdout + proc.stderr
        assert f"cannot write result file {result}: it is a FIFO" in proc.stderr, proc.stderr
        assert stat.S_ISFIFO(os.lstat(result).st_mode)
    else:
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert load_result(result).only.outcome == "passed"


SOURCE = '<testsuite name="s" tests="1"><testcase classname="c" name="t"/></testsuite>'


@pytest.mark.parametrize("output", ["fifo", "symlink to /dev/null", "regular file"])
def test_normalise_never_replaces_a_fifo_and_discards_into_dev_null(
    env: dict[str, str], tmp_path: Path, output: str
) -> None:
    source = tmp_path / "in.xml"
    source.write_text(SOURCE)
    target = tmp_path / "out.xml"
    if output == "fifo":
        os.mkfifo(target)
    elif output == "regular file":
        target.write_text("stale\n")
    else:
        target.symlink_to(os.devnull)
    before = os.lstat(target)
    proc = run_cli(["normalise", "--package-name", "p", str(source), "-o", str(target)], env)
    if output == "fifo":
        assert proc.returncode == 2, proc.stdout + proc.stderr
        line = the_error_line(proc)
        assert str(target) in line and "it is a FIFO" in line, line
        assert stat.S_ISFIFO(os.lstat(target).st_mode)
    elif output == "regular file":
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert os.lstat(target).st_ino != before.st_ino
        assert load_result(target).only.outcome == "passed"
    else:
        assert (proc.returncode, proc.stdout, proc.stderr) == (0, "", "")
        assert target.is_symlink() and os.readlink(target) == os.devnull
