"""Processes of a test run through the runner: tagged, waited for, found again, always killed.

Tests of the process tree start a runner in the background (:class:`Launcher`), wait for
the PIDs its test writes, signal it, and then check across the whole machine that
nothing carrying their tag (:data:`TAG_VAR` in the environment) outlived it. Teardown
kills whatever carries the tag, whatever went wrong. :func:`in_child` runs a short
Python program of a test in an interpreter of its own and reads back what it found: a
program that becomes a subreaper, ignores SIGCHLD or signals its whole tree must do it
away from pytest's own process and children.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest

from helpers.commands import CLI, HUNG
from helpers.domains import HIGH_IDS, free_ids
from helpers.processes import DEADLINE, poll_until
from helpers.results import load_result
from ros_isolated_test.process import proc

#: The variable every process of one test carries, with a value of its own.
TAG_VAR = "ROS_ISOLATED_TEST_PROCESS_TREE_TAG"
POOL_VAR = "ROS_ISOLATED_TEST_DOMAINS"
WAIT_VAR = "ROS_ISOLATED_TEST_WAIT_TIMEOUT"
#: A kernel command name with the characters that break naive parsing: spaces, ( and ).
AWKWARD_NAME = "a) b (c)) d"
#: Traps each forwarded signal, says which one came, exits 7.
TRAP_SCRIPT = (
    "trap 'echo INT > received; exit 7' INT; "
    "trap 'echo TERM > received; exit 7' TERM; "
    "trap 'echo HUP > received; exit 7' HUP; "
    "echo ready > ready; while :; do sleep 0.1; done"
)


def _stat_fields(pid: int) -> list[bytes] | None:
    try:
        data = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return None
    return data[data.rfind(b")") + 2 :].split()


def alive(pid: int) -> bool:
    """Running, not a zombie: a zombie no longer talks on any domain."""
    fields = _stat_fields(pid)
    return fields is not None and fields[0] != b"Z"


def children_of(pid: int) -> list[int]:
    found: list[int] = []
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            fields = _stat_fields(int(entry.name))
            if fields is not None and int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def environ_of(pid: int) -> list[bytes]:
    try:
        return Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    except OSError:
        return []


def tagged(tag: str) -> list[int]:
    """Every live process carrying the tag (a zombie's environment reads empty)."""
    wanted = f"{TAG_VAR}={tag}".encode()
    return [
        int(entry.name)
        for entry in os.scandir("/proc")
        if entry.name.isdigit() and wanted in environ_of(int(entry.name))
    ]


def describe(pids: Sequence[int]) -> str:
    lines = []
    for pid in pids:
        with contextlib.suppress(OSError):
            command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ")
            fields = _stat_fields(pid) or [b"?", b"?"]
            lines.append(f"{pid} ppid={fields[1].decode()} state={fields[0].decode()} {command!r}")
    return "\n".join(lines)


def kill_tagged(tag: str) -> None:
    deadline = time.monotonic() + 10
    while (pids := tagged(tag)) and time.monotonic() < deadline:
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.05)


def assert_no_survivors(tag: str) -> None:
    survivors = tagged(tag)
    assert not survivors, f"processes of the test outlived the runner:\n{describe(survivors)}"


def wait_for(
    condition: Callable[[], object],
    timeout: float,
    what: str,
    process: subprocess.Popen[bytes] | None = None,
    log: Path | None = None,
) -> None:
    """Poll ``condition``; fail at once if ``process`` ended first (its log says why)."""
    deadline = time.monotonic() + timeout
    while not condition():
        if process is not None and process.poll() is not None:
            output = log.read_text() if log is not None else ""
            pytest.fail(f"exited {process.returncode} before {what}:\n{output}")
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.02)


def read_pid(path: Path) -> int | None:
    """The PID a shell wrote to ``path``; None while the file is missing or half-written."""
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def wait_for_pid(
    path: Path,
    timeout: float = 30.0,
    process: subprocess.Popen[bytes] | None = None,
    log: Path | None = None,
) -> int:
    wait_for(lambda: read_pid(path) is not None, timeout, f"a PID in {path.name}", process, log)
    pid = read_pid(path)
    assert pid is not None
    return pid


class Launcher:
    """Background processes of one test; output goes to a file, never a pipe a leftover holds."""

    def __init__(self) -> None:
        self.processes: list[subprocess.Popen[bytes]] = []

    def start(
        self, args: Sequence[str], env: Mapping[str, str], log: Path, **kwargs: Any
    ) -> subprocess.Popen[bytes]:
        with log.open("wb") as handle:
            process = subprocess.Popen(
                list(args),
                env=dict(env),
                stdin=subprocess.DEVNULL,
                stdout=handle,
                stderr=subprocess.STDOUT,
                **kwargs,
            )
        self.processes.append(process)
        return process

    def stop(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.kill()
            process.wait()


@contextlib.contextmanager
def new_tag() -> Iterator[str]:
    """A value of :data:`TAG_VAR` of one test's own; its processes are killed at the end."""
    value = uuid.uuid4().hex
    try:
        yield value
    finally:
        kill_tagged(value)


@contextlib.contextmanager
def launching(tag: str) -> Iterator[Launcher]:
    """A :class:`Launcher`; at the end the tag's processes are killed, then what it started."""
    started = Launcher()
    try:
        yield started
    finally:
        kill_tagged(tag)
        started.stop()


def one_free_id() -> int:
    """One free high ID: a pool of one, so the next run must get the very same ID.

    Picked at random: other test runs on this machine take the same IDs' ports.
    """
    return free_ids(1, random.sample(HIGH_IDS, len(HIGH_IDS)))[0]


def tree_environment(env: Mapping[str, str], tag: str, domain: int) -> dict[str, str]:
    """Runners wait a little: another test run may hold the ID's port for a moment."""
    return {**env, TAG_VAR: tag, POOL_VAR: str(domain), WAIT_VAR: "20"}


def finish(process: subprocess.Popen[bytes], timeout: float, log: Path) -> int:
    try:
        return process.wait(timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"still running after {timeout:g} s; output so far:\n{log.read_text()}")


def start_trapping_test(
    launcher: Launcher,
    runner_args: Sequence[str],
    env: Mapping[str, str],
    tmp_path: Path,
    **popen: Any,
) -> tuple[subprocess.Popen[bytes], Path]:
    """``runner_args`` then ``sh -c`` :data:`TRAP_SCRIPT`, started; (runner, log) once ready."""
    log = tmp_path / "runner.log"
    runner = launcher.start([*runner_args, TRAP_SCRIPT], env, log, cwd=tmp_path, **popen)
    wait_for((tmp_path / "ready").exists, 30, "the test to start", runner, log)
    return runner, log


def interruption(result: Path) -> str:
    """The message and text of the one case of a run that did not pass (how it ended)."""
    case = load_result(result).only
    assert case.outcome in ("failure", "error"), case
    return f"{case.message}\n{case.text}"


def assert_interrupted_by(result: Path, signum: signal.Signals) -> None:
    """The result file says the run was interrupted, naming ``signum``."""
    message = interruption(result)
    assert "interrupted" in message and signum.name in message, message


def in_pid_namespace(*args: str) -> list[str]:
    """``ros-isolated-test ARGS`` as PID 1 of a PID namespace of its own (a container's)."""
    return ["unshare", "--pid", "--fork", "--mount-proc", CLI, *args]


def in_child(
    program: str,
    *args: object,
    env: Mapping[str, str] | None = None,
    prefix: Sequence[str] = (),
    **popen: Any,
) -> Any:
    """Run ``program`` (Python source) in an interpreter of its own; the JSON it printed last.

    The program sees ``sys.argv[1:]`` as ``args`` and prints one JSON document as its
    last line; ``prefix`` runs the interpreter (``unshare ...``), ``popen`` goes to
    subprocess (``user=...``). Its output goes to a file, never a pipe a process it left
    running could hold open. It failing fails the test, with its output.
    """
    with tempfile.TemporaryFile("w+") as output:
        done = subprocess.run(
            [*prefix, sys.executable, "-c", program, *map(str, args)],
            env=dict(os.environ if env is None else env),
            stdin=subprocess.DEVNULL,
            stdout=output,
            stderr=subprocess.STDOUT,
            timeout=HUNG,
            check=False,
            **popen,
        )
        output.seek(0)
        said = output.read()
    assert done.returncode == 0, f"the child failed ({done.returncode}):\n{said}"
    lines = said.strip().splitlines()
    assert lines, "the child printed nothing"
    return json.loads(lines[-1])


@contextlib.contextmanager
def awkward_sleeper(folder: Path) -> Iterator[subprocess.Popen[bytes]]:
    """A child whose executable (so whose kernel name) is :data:`AWKWARD_NAME`; killed after."""
    sleep = shutil.which("sleep")
    assert sleep is not None
    awkward = folder / AWKWARD_NAME
    shutil.copy(sleep, awkward)
    child = subprocess.Popen([str(awkward), "600", "0"], env={"MARKER": "one two", "X": "y"})
    try:
        poll_until(lambda: proc.cmdline(child.pid).startswith(str(awkward)), "the exec")
        yield child
    finally:
        child.kill()
        child.wait(DEADLINE)
