"""One test run to its end and its tree's end: how it ended, what it printed, what it left.

``supervisor.run`` starts the test (``spawn``), passes the runner's signals on
(``signals``), copies its output into the capture, enforces the timeout, ends what it
left (``sweep``) and says how it all ended (:class:`~supervisor.Outcome`). A signal may
come at any moment, also just as the test starts: it must still reach the test. A tree
that ignores SIGTERM gets SIGKILL after the grace, from a signal or the timeout. The
test stays in the runner's process group, as a shell's foreground job does, so it may
read a terminal's stdin without being stopped by SIGTTIN. Real processes, signals and a
real terminal; ``run`` itself is called in an interpreter of its own (it makes the
caller a subreaper for good).
"""

from __future__ import annotations

import contextlib
import os
import pty
import select
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from helpers.commands import CLI, run_cli
from helpers.process_tree import (
    Launcher,
    alive,
    assert_no_survivors,
    describe,
    finish,
    in_child,
    interruption,
    tagged,
    wait_for,
    wait_for_pid,
)

# --- supervisor.run itself --------------------------------------------------------------

#: ``supervisor.run`` of one case's command (argv: case, tag), kill grace 0.5 s. Prints
#: the Outcome, the console's bytes and how often ``on_start`` was called.
RUN = """
import io, json, os, signal, sys
from ros_isolated_test.process import supervisor
from ros_isolated_test.process.capture import OutputCapture
case, tag = sys.argv[1], sys.argv[2]
commands = {
    "exit": (["sh", "-c", "echo out; echo err >&2; exit 3"], None),
    "missing": (["rit-no-such-command"], None),
    "timeout": (["sleep", tag], 0.5),
    "in-time": (["true"], 600.0),
    "signalled": (["sleep", tag], None),
    "signalled-before": (["sleep", tag], None),
    "leftover": (["sh", "-c", f"sleep {tag} & echo started"], None),
}
command, timeout = commands[case]
started = []

def on_start():
    started.append(True)
    if case == "signalled":
        os.kill(os.getpid(), signal.SIGTERM)

if case == "signalled-before":
    # A real SIGTERM once the runner's handlers are in place, just before the test exists.
    spawn_test = supervisor.Test

    def signal_first(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        return spawn_test(*args, **kwargs)

    supervisor.Test = signal_first
console = io.BytesIO()
outcome = supervisor.run(command, dict(os.environ), OutputCapture(console), timeout, 0.5,
                         on_start=on_start)
error = outcome.start_error
print(json.dumps({
    "code": outcome.returncode, "signal": outcome.signal, "timed_out": outcome.timed_out,
    "received": outcome.received_signal, "leftovers": list(outcome.leftovers),
    "survivors": [stat.pid for stat in outcome.survivors], "started": len(started),
    "error": None if error is None else [type(error).__name__, error.filename],
    "output": console.getvalue().decode(), "took": outcome.duration >= 0,
}))
"""


def _run(case: str, tag: str) -> dict[str, Any]:
    found: dict[str, Any] = in_child(RUN, case, tag)
    return found


def test_run_streams_the_output_and_reports_the_exit_code(tags: Callable[[], str]) -> None:
    found = _run("exit", tags())
    assert (found["code"], found["signal"], found["error"]) == (3, None, None), found
    assert found["output"] == "out\nerr\n", "stdout and stderr, into the capture"
    assert found["started"] == 1 and found["took"], found
    assert not found["timed_out"] and found["received"] is None and found["leftovers"] == []


def test_a_command_that_cannot_start_is_a_start_error_not_an_exit_code(
    tags: Callable[[], str],
) -> None:
    found = _run("missing", tags())
    assert found["error"] == ["FileNotFoundError", "rit-no-such-command"], found
    assert found["code"] is None and found["started"] == 0, "no test, so no exit code"


def test_a_timeout_ends_the_test_with_sigterm_and_says_so(tags: Callable[[], str]) -> None:
    found = _run("timeout", tags())
    assert found["timed_out"] and found["signal"] == signal.SIGTERM, found
    assert found["code"] == -signal.SIGTERM and found["received"] is None, found
    control = _run("in-time", tags())
    assert not control["timed_out"] and control["code"] == 0, control


def test_a_signal_as_the_test_starts_is_passed_on_and_reported(tags: Callable[[], str]) -> None:
    """Sent from ``on_start``: the test exists, and the runner's handlers are in place."""
    found = _run("signalled", tags())
    assert found["received"] == signal.SIGTERM, found
    assert found["signal"] == signal.SIGTERM, "the test got it, and ended on it"
    assert not found["timed_out"], found


def test_a_signal_before_the_test_exists_still_reaches_it(tags: Callable[[], str]) -> None:
    """Noted while no test could get it, passed on once it exists: SIGTERM, not the SIGKILL
    the grace would end in."""
    found = _run("signalled-before", tags())
    assert found["received"] == signal.SIGTERM and found["started"] == 1, found
    assert found["signal"] == signal.SIGTERM, found


def test_a_leftover_holding_the_output_pipe_does_not_hold_the_run(
    tags: Callable[[], str],
) -> None:
    """The test exits, its background ``sleep`` keeps the pipe open: ended and named."""
    tag = tags()
    found = _run("leftover", tag)
    assert found["code"] == 0 and found["output"] == "started\n", found
    assert [name.endswith("(sleep)") for name in found["leftovers"]] == [True], found
    assert found["survivors"] == [], found


# --- through the runner -----------------------------------------------------------------


def test_signal_as_the_test_starts_still_reaches_the_test(
    tree_env: dict[str, str], tag: str, tmp_path: Path
) -> None:
    """Ctrl-C or a container stop can come at any moment, also just as the test starts.

    The test signals its runner as its very first act, so the signal surely comes after
    the test started: "it never ran" would be false, and its process left running. The
    runner runs at batch priority on one CPU while the test (reset to normal priority)
    starts, as on a loaded machine where the runner is descheduled just then.
    """
    cpu = min(os.sched_getaffinity(0))

    def deprioritise() -> None:
        os.sched_setaffinity(0, {cpu})
        policy = os.SCHED_BATCH | os.SCHED_RESET_ON_FORK
        os.sched_setscheduler(0, policy, os.sched_param(0))

    for round_ in range(2):
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            result = tmp_path / f"{signum.name}-{round_}.xml"
            script = f"kill -{signum.name[3:]} $PPID; exec sleep 30"
            args = ["run", "--junit-xml", str(result), "--", "sh", "-c", script]
            proc = run_cli(args, tree_env, cwd=tmp_path, preexec_fn=deprioritise)
            output = proc.stdout + proc.stderr
            survivors = tagged(tag)
            assert not survivors, f"{signum.name}: left running:\n{describe(survivors)}\n{output}"
            message = interruption(result)
            assert "never ran" not in message, f"{signum.name}: the test did run:\n{output}"
            assert "interrupted" in message and signum.name in message, message
            assert proc.returncode == 128 + signum, output


def test_child_ignoring_sigterm_is_killed_after_the_grace(
    tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    grace = 1.0
    stubborn = "trap '' TERM; echo $$ > child.pid; while :; do sleep 0.1; done"
    script = f'sh -c "{stubborn}" & echo ready > ready; wait'
    result = tmp_path / "result.xml"
    args = [CLI, "run", "--kill-grace", f"{grace:g}", "--junit-xml", str(result)]
    log = tmp_path / "runner.log"
    runner = launcher.start([*args, "--", "sh", "-c", script], tree_env, log, cwd=tmp_path)
    wait_for((tmp_path / "ready").exists, 30, "the test to start", runner, log)
    child = wait_for_pid(tmp_path / "child.pid")
    started = time.monotonic()
    os.kill(runner.pid, signal.SIGTERM)
    # The child would loop for ever: only the SIGKILL after the grace ends the runner.
    code = finish(runner, 60, log)
    elapsed = time.monotonic() - started

    assert elapsed >= grace, f"the runner ended {elapsed:.1f} s after SIGTERM: no grace given"
    assert code == 128 + signal.SIGTERM, log.read_text()
    assert not alive(child)
    assert_no_survivors(tag)
    assert "SIGTERM" in interruption(result)


def test_timeout_kills_a_tree_that_ignores_sigterm(
    tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    script = (
        "trap '' TERM; sh -c 'sleep 60 & echo $! > grandchild.pid; wait' & "
        "while :; do sleep 0.1; done"
    )
    result = tmp_path / "result.xml"
    args = [CLI, "run", "--timeout", "1", "--kill-grace", "1", "--junit-xml", str(result)]
    log = tmp_path / "runner.log"
    runner = launcher.start([*args, "--", "sh", "-c", script], tree_env, log, cwd=tmp_path)
    grandchild = wait_for_pid(tmp_path / "grandchild.pid", process=runner, log=log)
    # The tree ignores SIGTERM and loops for ever: only the timeout's SIGKILL ends it.
    code = finish(runner, 60, log)

    assert code == 124, log.read_text()
    assert not alive(grandchild)
    assert_no_survivors(tag)
    message = interruption(result)
    assert "timed out" in message and "--timeout 1" in message, message


def test_test_reads_a_terminal_without_being_stopped(
    tree_env: dict[str, str], tag: str, tmp_path: Path
) -> None:
    """A runner in a terminal's foreground group: its test reads stdin, not SIGTTIN-stopped."""
    args = [CLI, "run", "--", "sh", "-c", "read line; echo got:$line"]
    pid, master = pty.fork()
    if pid == 0:  # the child: session leader, the terminal's foreground group
        try:
            os.chdir(tmp_path)
            os.execve(CLI, args, tree_env)
        finally:
            os._exit(127)
    output = b""
    written = False
    status: int | None = None
    deadline = time.monotonic() + 30
    try:
        while time.monotonic() < deadline:
            if not written and b"Running with ROS_DOMAIN_ID" in output:
                os.write(master, b"hello\n")
                written = True
            ready, _, _ = select.select([master], [], [], 0.1)
            if ready:
                try:
                    chunk = os.read(master, 4096)
                except OSError:  # EIO: every process on the terminal's side is gone
                    chunk = b""
                output += chunk
                if chunk:
                    continue
            finished, raw = os.waitpid(pid, os.WNOHANG)
            if finished:
                status = raw
                break
        if status is None:
            stuck = describe(tagged(tag))
            pytest.fail(f"the runner did not end (stopped by SIGTTIN?):\n{stuck}\n{output!r}")
    finally:
        if status is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        os.close(master)
    assert b"got:hello" in output, output
    assert os.waitstatus_to_exitcode(status) == 0, output
