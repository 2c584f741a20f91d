"""Where the suite's programs are, and how tests run the CLI and the RUNNER as real processes.

Every test that starts ``ros-isolated-test`` or the ctest RUNNER goes through here, so all
of them run the same installed entry points with the same timeout and captured text.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

TYPE_CHECKING = False
if TYPE_CHECKING:
    from helpers.distros import Tools

REPO = Path(__file__).resolve().parents[2]
#: The virtualenv's bin/, where the CLI, colcon and the test tools are installed.
BIN = Path(sys.executable).parent
CLI = str(BIN / "ros-isolated-test")
#: Variables that would change what the runner decides; tests set them explicitly.
POLICY_VARS = (
    "ROS_DOMAIN_ID",
    "DISABLE_ROS_ISOLATION",
    "ROS_ISOLATED_TEST_DOMAINS",
    "ROS_ISOLATED_TEST_LOCK_DIR",
    "ROS_ISOLATED_TEST_HELD_DOMAIN_ID",
    "ROS_ISOLATED_TEST_RERUNS",
    "ROS_ISOLATED_TEST_RESOURCES",
    "ROS_ISOLATED_TEST_CAPACITY",
    "ROS_ISOLATED_TEST_WAIT_TIMEOUT",
    "ROS_ISOLATED_TEST_GZ_PARTITION",
    "ROS_ISOLATED_TEST_SHARD",
    "ROS_ISOLATED_TEST_DURATIONS",
    "ROS_ISOLATED_TEST_HISTORY",
    "GZ_PARTITION",
    "IGN_PARTITION",
)
#: Only stops a hung test; no test's verdict depends on it.
HUNG = 120


def run_process(
    argv: Sequence[str], env: Mapping[str, str], **kwargs: object
) -> subprocess.CompletedProcess[str]:
    """One of our programs as a real process, output captured as text, hangs stopped."""
    return subprocess.run(  # type: ignore[call-overload, no-any-return]
        list(argv),
        check=False,
        env=dict(env),
        capture_output=True,
        text=True,
        timeout=HUNG,
        **kwargs,
    )


def run_cli(
    args: Sequence[str], env: Mapping[str, str], **kwargs: object
) -> subprocess.CompletedProcess[str]:
    """``ros-isolated-test ARGS`` as a real process, output captured as text."""
    return run_process([CLI, *args], env, **kwargs)


def run_runner(
    runner_script: str, args: Sequence[str], env: Mapping[str, str], **kwargs: object
) -> subprocess.CompletedProcess[str]:
    """The RUNNER script exactly as ctest calls it: ``python3 -u <script> ARGS``."""
    return run_process([sys.executable, "-u", runner_script, *args], env, **kwargs)


#: How every runner error line starts.
ERROR_PREFIX = "ros-isolated-test: error: "
#: The two ways a test is run: ``run`` from a shell, and the ctest RUNNER script.
MODES = ["shell", "runner"]


def through(
    mode: str,
    runner_script: str,
    env: dict[str, str],
    cwd: Path,
    command: Sequence[str],
    result: Path | None = None,
    runner_options: Sequence[str] = (),
    tools: Tools | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run ``command`` through ``ros-isolated-test run`` (``mode`` "shell") or the RUNNER.

    The RUNNER writes ``result`` (default ``cwd/pkg/t.xml``) with
    ``--generate-result-on-success`` and ``runner_options``. With ``tools``, the CLI and the
    RUNNER's interpreter are that distro's; else the suite's.
    """
    if mode == "shell":
        assert not runner_options
        junit = ["--junit-xml", str(result)] if result is not None else []
        cli = run_cli if tools is None else tools.run_cli
        return cli(["run", *junit, "--", *command], env, cwd=cwd)
    result = result if result is not None else cwd / "pkg" / "t.xml"
    args = ament_args(result, command, "--generate-result-on-success", *runner_options)
    runner = run_runner if tools is None else tools.run_runner
    return runner(runner_script, args, env, cwd=cwd)


def the_error_line(proc: subprocess.CompletedProcess[str]) -> str:
    """The runner's one line on stderr, which must start with :data:`ERROR_PREFIX`."""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, f"expected exactly one line on stderr, got:\n{proc.stderr}"
    assert lines[0].startswith(ERROR_PREFIX), lines[0]
    return lines[0]


def ament_args(
    result: Path, command: Sequence[str], *options: str, package: str = "pkg"
) -> list[str]:
    """run_test.py's arguments as ctest passes them: ``RESULT --package-name P ... --command``."""
    return [str(result), "--package-name", package, *options, "--command", *command]


def ament(
    runner_script: str,
    result: Path,
    command: Sequence[str],
    env: Mapping[str, str],
    *options: str,
    cwd: Path,
    package: str = "pkg",
    tools: Tools | None = None,
) -> subprocess.CompletedProcess[str]:
    """``python3 -u RUNNER RESULT --package-name P OPTIONS --command CMD``, as ctest runs it.

    With ``tools``, the interpreter is that distro's; else the suite's.
    """
    args = ament_args(result, command, *options, package=package)
    runner = run_runner if tools is None else tools.run_runner
    return runner(runner_script, args, env, cwd=cwd)


def normalise(source: Path, output: Path, env: Mapping[str, str], package: str) -> None:
    """``ros-isolated-test normalise``: the runner's own normalisation, for a given file."""
    proc = run_cli(["normalise", "--package-name", package, str(source), "-o", str(output)], env)
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    assert output.is_file(), proc.stdout + proc.stderr


def start_cli(
    args: Sequence[str], env: Mapping[str, str], log: Path, into: list[subprocess.Popen[bytes]]
) -> subprocess.Popen[bytes]:
    """``ros-isolated-test ARGS`` in the background, output into ``log``, kept in ``into``.

    ``into`` is the ``started`` fixture's list: whatever is still running is killed at the end.
    """
    return start_process([CLI, *args], env, log, into)


def start_process(
    argv: Sequence[str],
    env: Mapping[str, str],
    log: Path,
    into: list[subprocess.Popen[bytes]],
    **popen: object,
) -> subprocess.Popen[bytes]:
    """``argv`` in the background, logged, kept in ``into``: the one Popen of every start_*."""
    with log.open("wb") as out:
        process: subprocess.Popen[bytes] = subprocess.Popen(  # type: ignore[call-overload]
            list(argv),
            env=dict(env),
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=out,
            **popen,
        )
    into.append(process)
    return process


def start_runner(
    runner_script: str,
    args: Sequence[str],
    env: Mapping[str, str],
    log: Path,
    into: list[subprocess.Popen[bytes]],
    **popen: object,
) -> subprocess.Popen[bytes]:
    """The RUNNER script in the background as ctest starts it, output into ``log``.

    Kept in ``into`` (the ``started`` fixture's list); ``popen`` goes to Popen, e.g.
    ``start_new_session=True`` for a process group of its own that a test kills whole.
    """
    return start_process([sys.executable, "-u", runner_script, *args], env, log, into, **popen)
