"""``cli`` run: ``ros-isolated-test run -- CMD`` as a real process, as a user runs it.

Its exit code is the command's (128+N for a signal, 124 for --timeout, 126/127 when it
cannot be run), its output reaches --output-file and its outcome the --junit-xml file; a
closed stdout, stderr or stdin never stops it; the output file and the result file cannot
be one file; SIGTERM to the runner is passed on to the test. The same promises of the
ctest RUNNER script are checked beside it (``mode`` "runner"), and the RUNNER started by
a Python that lacks the package finds the CLI's. Each refusal has its control.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.cli_runs import TOUCH
from helpers.commands import BIN, CLI, HUNG, ament, ament_args, run_cli, the_error_line
from helpers.results import load_result


def run(args: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return run_cli(["run", *args], env, cwd=cwd)


#: The --timeout tests' guard: a test that --timeout did not stop (a ``sleep 30``) fails on
#: it (TimeoutExpired) instead of ending by itself.
STOPPED_WITHIN = 20


def run_stopped(
    args: list[str], env: dict[str, str], cwd: Path
) -> subprocess.CompletedProcess[str]:
    """``run ARGS`` as a real process, stopped after STOPPED_WITHIN seconds at the most."""
    return subprocess.run(
        [CLI, "run", *args],
        env=env,
        cwd=cwd,
        capture_output=True,
        check=False,
        text=True,
        timeout=STOPPED_WITHIN,
    )


# --- exit codes ----------------------------------------------------------------------------------


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
    proc = run_stopped(
        ["--timeout", "1", "--junit-xml", str(result), "--", "sleep", "30"], env, tmp_path
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
    proc = run_stopped(
        ["--timeout", "0.5", "--kill-grace", "0.5", "--", sys.executable, "-c", stubborn],
        env,
        tmp_path,
    )
    assert proc.returncode == 124, proc.stdout + proc.stderr
    assert "ignoring TERM" in proc.stdout


def test_timeout_still_applies_after_the_test_closed_its_output(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A test that closes stdout and stderr (a daemon-style node) must still be stopped."""
    result = tmp_path / "r.xml"
    quiet = "exec >/dev/null 2>&1; exec sleep 3"
    proc = run_stopped(
        ["--timeout", "1", "--junit-xml", str(result), "--", "sh", "-c", quiet], env, tmp_path
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
        # The order of events, no clock: the runner ends the tree before it exits.
        assert not _alive(child), "the test's child outlived the runner after the timeout"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(child, signal.SIGKILL)


# --- files ---------------------------------------------------------------------------------------


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


# --- A.1: a closed stdout, stderr or stdin never stops the run -----------------------------------


@pytest.mark.parametrize("closed", [">&-", "2>&-", "<&-", ">&- 2>&- <&-"])
@pytest.mark.parametrize("mode", ["run", "runner"])
def test_a_closed_standard_stream_still_runs_the_test_and_writes_the_result(
    env: dict[str, str], runner_script: str, tmp_path: Path, closed: str, mode: str
) -> None:
    result = tmp_path / "pkg" / "r.xml"
    command = ["sh", "-c", "touch ran; echo hello; exit 3"]
    if mode == "run":
        argv = [CLI, "run", "--junit-xml", str(result), "--", *command]
    else:
        argv = [sys.executable, "-u", runner_script, str(result), "--command", *command]
    # The shell closes the descriptor, then execs the runner: it starts without it.
    done = subprocess.run(
        ["sh", "-c", f'exec "$@" {closed}', "sh", *argv],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=HUNG,
        check=False,
    )
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 3, done.stdout + done.stderr
    assert (tmp_path / "ran").exists()
    case = load_result(result).only
    assert case.outcome == "failure"
    assert "exited with code 3" in case.message
    if ">&-" not in closed.replace("2>&-", ""):
        assert "hello" in done.stdout  # control: with stdout open, the output is there


# --- A.5: the output file and the result file cannot be one file ---------------------------------


def _same_file_spellings(tmp_path: Path) -> dict[str, tuple[str, str]]:
    (tmp_path / "link.xml").symlink_to("r.xml")
    return {
        "identical": ("r.xml", "r.xml"),
        "dot-slash": ("r.xml", "./r.xml"),
        "absolute": ("r.xml", str(tmp_path / "r.xml")),
        "symlink": ("r.xml", "link.xml"),
    }


@pytest.mark.parametrize("spelling", ["identical", "dot-slash", "absolute", "symlink"])
@pytest.mark.parametrize("mode", ["run", "runner"])
def test_output_file_equal_to_the_result_file_is_a_usage_error(
    env: dict[str, str], runner_script: str, tmp_path: Path, spelling: str, mode: str
) -> None:
    result, output = _same_file_spellings(tmp_path)[spelling]
    if mode == "run":
        proc = run_cli(
            ["run", "--junit-xml", result, "--output-file", output, "--", *TOUCH],
            env,
            cwd=tmp_path,
        )
    else:
        proc = ament(runner_script, Path(result), TOUCH, env, "--output-file", output, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    line = the_error_line(proc)
    assert "--output-file" in line and "result file" in line, line
    assert load_result(tmp_path / "r.xml").only.outcome == "error"


@pytest.mark.parametrize("mode", ["run", "runner"])
def test_distinct_output_and_result_files_both_are_written(
    env: dict[str, str], runner_script: str, tmp_path: Path, mode: str
) -> None:
    """Control: a different output file beside the result file is fine."""
    command = ("sh", "-c", "touch ran; echo hello")
    if mode == "run":
        proc = run_cli(
            ["run", "--junit-xml", "r.xml", "--output-file", "./out.log", "--", *command],
            env,
            cwd=tmp_path,
        )
    else:
        proc = ament(
            runner_script,
            Path("r.xml"),
            command,
            env,
            "--output-file",
            "out.log",
            "--generate-result-on-success",
            cwd=tmp_path,
        )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "hello" in (tmp_path / "out.log").read_text()
    assert load_result(tmp_path / "r.xml").only.outcome == "passed"


# --- signals to the runner -----------------------------------------------------------------------


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
            *ament_args(result, command, "--generate-result-on-success"),
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


# --- the RUNNER script with a Python that lacks the package --------------------------------------


def run_bare(
    python: str, path: str, lock_dir: Path, runner_script: str, args: list[str], cwd: Path
) -> subprocess.CompletedProcess[str]:
    """The RUNNER under ``python`` with nothing but PATH and the lock dir: both tests below."""
    return subprocess.run(
        ["/usr/bin/env", "-i", f"PATH={path}", f"ROS_ISOLATED_TEST_LOCK_DIR={lock_dir}",
         python, "-u", runner_script, *args],
        capture_output=True, check=False, text=True, timeout=60, cwd=cwd,
    )  # fmt: skip


@capabilities.BARE_PYTHON
def test_runner_script_reexecs_with_the_clis_python(
    runner_script: str, lock_dir: Path, tmp_path: Path
) -> None:
    python = capabilities.bare_python()
    assert python is not None
    result = tmp_path / "pkg" / "t.xml"
    # The runner's own command line, read by the test: it must be the venv's interpreter.
    command = ["sh", "-c", "tr '\\0' ' ' < /proc/$PPID/cmdline; echo"]
    args = ament_args(result, command, "--generate-result-on-success")
    proc = run_bare(python, f"{BIN}:/usr/bin:/bin", lock_dir, runner_script, args, tmp_path)
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
    args = [str(tmp_path / "t.xml"), "--command", "touch", "ran"]
    proc = run_bare(python, "/usr/bin:/bin", lock_dir, runner_script, args, tmp_path)
    assert proc.returncode == 2
    assert not (tmp_path / "ran").exists()
    assert "cannot import ros-isolated-test" in proc.stderr
    assert "Python3_EXECUTABLE" in proc.stderr
