"""The test's main process starts as Popen would start it, and its exit status is never lost.

``spawn.Test`` starts it with ``posix_spawn``: found on the test's own PATH (a match
that cannot run gives way to the next, as execvp does), with SIGPIPE and SIGXFSZ at
their default (Python ignores both, and a test would inherit that), with none of the
runner's other descriptors, and stdout and stderr on a pipe above 0-2 even when the
runner was started with those closed. ``child_statuses_kept`` puts SIGCHLD at its
default while the test runs: ignored, the kernel would reap the test and its status
would be lost. Real processes; each promise has its control (what Popen or an ignored
SIGCHLD does without it).
"""

from __future__ import annotations

import os
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers.commands import HUNG
from helpers.process_tree import in_child

from ros_isolated_test.process import spawn


def _finished(test: spawn.Test) -> tuple[int | None, str]:
    """Its exit code and everything it wrote, once it has ended."""
    output = b""
    try:
        while chunk := os.read(test.stdout, 65536):
            output += chunk
    finally:
        os.close(test.stdout)
    return test.wait(), output.decode()


def _ignored(status: str) -> set[int]:
    """The signals a ``/proc/<pid>/status`` says are ignored."""
    (line,) = [line for line in status.splitlines() if line.startswith("SigIgn:")]
    mask = int(line.split()[1], 16)
    return {signum for signum in range(1, 65) if mask & (1 << (signum - 1))}


SHOW_STATUS = ["sh", "-c", "cat /proc/self/status"]


def test_the_test_gets_sigpipe_and_sigxfsz_at_their_default(env: dict[str, str]) -> None:
    code, output = _finished(spawn.Test(SHOW_STATUS, env))
    assert code == 0, output
    assert not _ignored(output) & {signal.SIGPIPE, signal.SIGXFSZ}
    # The control: started as this Python process is, both stay ignored.
    inherited = subprocess.run(
        SHOW_STATUS, capture_output=True, text=True, restore_signals=False, check=True
    )
    assert {signal.SIGPIPE, signal.SIGXFSZ} <= _ignored(inherited.stdout)


@pytest.fixture
def inherited_fd() -> Iterator[int]:
    """An inheritable descriptor of the runner's, as a jobserver or a parent's pipe is."""
    read_end, write_end = os.pipe()
    fd = os.dup2(write_end, 200, inheritable=True)
    try:
        yield fd
    finally:
        for end in (read_end, write_end, fd):
            os.close(end)


def test_the_test_inherits_no_descriptor_of_the_runner(
    env: dict[str, str], inherited_fd: int
) -> None:
    look = ["sh", "-c", f"[ -e /proc/self/fd/{inherited_fd} ] && echo open || echo closed"]
    code, output = _finished(spawn.Test(look, env))
    assert (code, output) == (0, "closed\n")
    assert os.get_inheritable(inherited_fd), "the runner's descriptor is put back as it was"
    # The control: a child that inherits descriptors sees it open.
    shown = subprocess.run(look, capture_output=True, text=True, close_fds=False, check=True)
    assert shown.stdout == "open\n"


def _program(path: Path, text: str, mode: int = 0o755) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    path.chmod(mode)


def test_the_command_is_found_on_the_tests_own_path_as_execvp_does(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A match whose interpreter is missing gives way to the next match on the PATH."""
    _program(tmp_path / "first" / "rit-tool", "#!/nonexistent/interpreter\n")
    _program(tmp_path / "second" / "rit-tool", "#!/bin/sh\necho the second\n")
    path = f"{tmp_path / 'first'}{os.pathsep}{tmp_path / 'second'}{os.pathsep}{env['PATH']}"
    code, output = _finished(spawn.Test(["rit-tool"], {**env, "PATH": path}))
    assert (code, output) == (0, "the second\n")
    # The control: on the runner's own PATH there is no such command.
    with pytest.raises(FileNotFoundError) as missing:
        spawn.Test(["rit-tool"], env)
    assert missing.value.filename == "rit-tool", "named as given, not as found"


def test_a_command_that_cannot_run_raises_its_own_error_not_missing(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A match that is not executable is the error kept, over a later "missing" one."""
    _program(tmp_path / "first" / "rit-tool", "#!/bin/sh\necho ran\n", mode=0o644)
    _program(tmp_path / "second" / "rit-tool", "#!/nonexistent/interpreter\n")
    path = f"{tmp_path / 'first'}{os.pathsep}{tmp_path / 'second'}{os.pathsep}{env['PATH']}"
    with pytest.raises(PermissionError) as refused:
        spawn.Test(["rit-tool"], {**env, "PATH": path})
    assert refused.value.filename == "rit-tool"
    with pytest.raises(FileNotFoundError):  # the control: nowhere on the PATH at all
        spawn.Test(["rit-no-such-tool"], {**env, "PATH": path})


#: Under an ignored SIGCHLD (a launcher may pass that on): a test exiting 3, started with
#: and without ``child_statuses_kept``. Prints the codes and SIGCHLD's handler around it.
LOST_STATUS = """
import json, os, signal, sys
from ros_isolated_test.process.spawn import Test, child_statuses_kept
signal.signal(signal.SIGCHLD, signal.SIG_IGN)

def run():
    test = Test(["sh", "-c", "exit 3"], dict(os.environ))
    os.close(test.stdout)
    return test.wait(), test.status_lost

with child_statuses_kept():
    during = signal.getsignal(signal.SIGCHLD) == signal.SIG_DFL
    kept, kept_lost = run()
after = signal.getsignal(signal.SIGCHLD) == signal.SIG_IGN
lost, lost_lost = run()
print(json.dumps({"during": during, "after": after, "kept": [kept, kept_lost],
                  "lost": [lost, lost_lost]}))
"""


def test_the_exit_status_is_kept_when_sigchld_was_ignored() -> None:
    found = in_child(LOST_STATUS)
    assert found["kept"] == [3, False], found
    assert found["during"] and found["after"], "SIGCHLD is default while, ignored again after"
    # The control: without it the kernel reaps the test, and that is never called a pass.
    assert found["lost"] == [spawn.STATUS_LOST, True], found


#: A runner started with stdin and stdout closed: its test's output must still reach the
#: pipe, never the runner's own (closed) streams. Prints the pipe's end and the output.
CLOSED_STDIO = """
import json, os, sys
from ros_isolated_test.process.spawn import Test
saved = os.dup(1)
os.close(0)
os.close(1)
test = Test(["sh", "-c", "echo out; echo err >&2"], dict(os.environ))
output = b""
while chunk := os.read(test.stdout, 4096):
    output += chunk
code = test.wait()
os.dup2(saved, 1)
print(json.dumps({"fd": test.stdout, "code": code, "output": output.decode()}))
"""


def test_the_output_pipe_is_above_stdio_when_the_runner_has_them_closed() -> None:
    found = in_child(CLOSED_STDIO)
    assert found["fd"] > 2, found
    assert (found["code"], found["output"]) == (0, "out\nerr\n"), found


def test_the_test_is_the_runners_child_and_its_signal_is_its_exit_code(
    env: dict[str, str],
) -> None:
    """``poll`` says None while it runs; killed by a signal, the code is minus the signal."""
    test = spawn.Test(["sleep", "600"], env)
    try:
        assert test.poll() is None
        assert test.wait(0.05) is None, "wait with a timeout returns while it still runs"
        os.kill(test.pid, signal.SIGTERM)
        assert test.wait(HUNG) == -signal.SIGTERM
        assert test.poll() == -signal.SIGTERM and not test.status_lost
    finally:
        os.close(test.stdout)
        if test.returncode is None:
            os.kill(test.pid, signal.SIGKILL)
            test.wait()
