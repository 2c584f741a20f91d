"""``interrupts``: a signal ends a pytest session as Ctrl-C does, and its leftovers still end.

SIGTERM or SIGHUP (ctest's or colcon's timeout, a CI cancel) ends pytest as Ctrl-C does,
the sweep runs, and a second signal cannot cut it short; a test that swallows the
interrupt does not keep the session going. Under xdist the controller
passes the signal on to its workers and waits for them; a worker whose controller was
killed still sweeps and releases. Controls: Ctrl-C with xdist, SIGTERM without; status
shows each ID held while the tests run. The release's order without a signal is
test_holding_release.py's.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path

import pytest
from helpers.commands import CLI, HUNG
from helpers.processes import carrying, poll_until, wait_for
from helpers.pytest_sessions import (
    NEXT_TEST,
    project,
    run_in,
    run_pytest,
    start_pytest,
)

#: Forks a child without exec (it inherits everything, the lock too) that ignores SIGTERM.
FORKING_TEST = """\
import os, pathlib, signal, time

def test_forks_and_waits():
    events, pid_file = os.environ["EVENTS"], os.environ["PID_FILE"]
    if os.fork() == 0:
        def noted(signum, frame):
            with open(events, "a") as out:
                out.write("child got SIGTERM\\n")
        signal.signal(signal.SIGTERM, noted)
        pathlib.Path(pid_file + ".new").write_text(str(os.getpid()))
        os.rename(pid_file + ".new", pid_file)  # whole, never seen empty
        while True:
            time.sleep(1)
    time.sleep(120)
"""


@pytest.mark.parametrize("signum", [15, 1])
def test_a_signal_ends_the_tests_leftovers_before_the_release(
    tmp_path: Path,
    env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    signum: int,
) -> None:
    """SIGTERM or SIGHUP (ctest's timeout): the sweep runs, and a second one cannot cut it."""
    events, pid_file = tmp_path / "events", tmp_path / "child.pid"
    shared = {**one_id, "EVENTS": str(events), "PID_FILE": str(pid_file)}
    log = tmp_path / "pytest.log"
    session = start_pytest(project(tmp_path / "forking", FORKING_TEST), shared, log, started)
    wait_for(pid_file)
    child = int(pid_file.read_text())
    session.send_signal(signum)
    poll_until(
        lambda: session.poll() is not None or (events.exists() and bool(events.read_text())),
        "the sweep's SIGTERM reached the child, or pytest ended",
    )
    assert events.exists() and events.read_text() == "child got SIGTERM\n", log.read_text()
    session.send_signal(signum)  # during the grace: only noted
    assert session.wait(HUNG) == pytest.ExitCode.INTERRUPTED, log.read_text()
    assert not Path(f"/proc/{child}").exists()
    assert f"stopped process {child}" in log.read_text()
    # The ID is free at once: the next session gets it without waiting.
    following = project(tmp_path / "following", NEXT_TEST)
    after = run_pytest(following, {**shared, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}, "test")
    assert after.returncode == 0, after.stdout + after.stderr


#: The first test swallows the interrupt (as launch_pytest's wait for its launch does: its
#: KeyboardInterrupt becomes an AttributeError); the second notes that it ran.
SWALLOWING_TEST = """\
import os, pathlib, time

def test_swallows_the_interrupt():
    pathlib.Path(os.environ["READY"]).touch()
    try:
        time.sleep(300)
    except KeyboardInterrupt:
        pass

def test_runs_next():
    pathlib.Path(os.environ["NEXT"]).touch()
"""


@pytest.mark.parametrize("signum", [15, None], ids=["sigterm", "no-signal"])
def test_a_swallowed_signal_still_ends_the_session(
    tmp_path: Path,
    env: dict[str, str],
    one_id: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    signum: int | None,
) -> None:
    """SIGTERM once (a ctest or colcon timeout), caught by a test: no later test runs and
    pytest exits 2, never a pass. The control: no signal, the swallowing test ends by
    itself (GO) and the next test runs."""
    ready, following = tmp_path / "ready", tmp_path / "next"
    shared = {**one_id, "READY": str(ready), "NEXT": str(following)}
    if signum is None:  # the control: the sleep ends by itself, early
        test = SWALLOWING_TEST.replace("time.sleep(300)", "time.sleep(0)")
    else:
        test = SWALLOWING_TEST
    log = tmp_path / "pytest.log"
    session = start_pytest(project(tmp_path / "pkg", test), shared, log, started)
    wait_for(ready)
    if signum is not None:
        session.send_signal(signum)
        assert session.wait(HUNG) == pytest.ExitCode.INTERRUPTED, log.read_text()
        assert not following.exists(), log.read_text()
    else:
        assert session.wait(HUNG) == pytest.ExitCode.OK, log.read_text()
        assert following.exists(), log.read_text()


# --- a signal to the xdist controller, or the controller killed ----------------------------------


#: Two tests (one per xdist worker): each starts a long-lived child that ignores SIGINT (a
#: terminal's Ctrl-C reaches it too: only the sweep's SIGTERM ends it), names it in a file
#: named after its own process (the worker), then runs on until interrupted.
RUNNING_TEST = """\
import os, pathlib, subprocess, sys, time
import pytest

CHILD = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(300)"

@pytest.mark.parametrize("n", range(2))
def test_runs_on(n):
    child = subprocess.Popen([sys.executable, "-c", CHILD])
    started = pathlib.Path(os.environ["STARTED"])
    (started / f"{os.getpid()}.new").write_text(str(child.pid))
    os.rename(started / f"{os.getpid()}.new", started / str(os.getpid()))  # whole, never empty
    time.sleep(300)
"""


#: Where a session's processes are found: in their environment, whatever their names.
MARK_VAR = "RIT_SESSION_MARK"


@pytest.fixture
def session_mark() -> Iterator[str]:
    """``RIT_SESSION_MARK=<uuid>`` for a session's environment; whatever still carries it
    when the test ends (it failed) is killed, so nothing of it outlives the test."""
    entry = f"{MARK_VAR}={uuid.uuid4().hex}"
    yield entry
    for pid in carrying(entry):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def running_tests(folder: Path) -> dict[int, int]:
    """Each running test's process (an xdist worker) and its child, as their files say."""
    return {int(path.name): int(path.read_text()) for path in folder.glob("[0-9]*[0-9]")}


def held_rows(env: Mapping[str, str], cwd: Path) -> list[dict[str, object]]:
    """``status --json`` rows of the lock directory that hold an ID: a lock or a survivor."""
    listed = run_in(cwd, env, [CLI, "status", "--json"])
    assert listed.returncode == 0, listed.stderr
    rows: list[dict[str, object]] = json.loads(listed.stdout)
    return [row for row in rows if row["via"] in ("lock", "survivor")]


def start_running_tests(
    tmp_path: Path,
    env: Mapping[str, str],
    mark: str,
    workers: int,
    into: list[subprocess.Popen[bytes]],
) -> tuple[subprocess.Popen[bytes], Path, dict[int, int]]:
    """pytest (``-n workers``, 0: no xdist) on RUNNING_TEST in a ROS package, in a process
    group of its own, the environment marked; once every test runs: pytest, its log, and
    each test's process with its child."""
    started_dir = tmp_path / "started"
    started_dir.mkdir()
    name, value = mark.split("=", 1)
    session_env = {**env, "STARTED": str(started_dir), name: value}
    root = project(tmp_path / "pkg", RUNNING_TEST)
    log = tmp_path / "pytest.log"
    xdist = ("-n", str(workers)) if workers else ()
    session = start_pytest(root, session_env, log, into, (*xdist, "test"), start_new_session=True)
    expected = max(workers, 1)  # without xdist the tests run one after the other
    poll_until(
        lambda: len(running_tests(started_dir)) >= expected,
        f"{expected} test(s) running, each with its child",
    )
    children = running_tests(started_dir)
    # The control for the checks after: while the tests run, status shows each ID held by
    # the process that runs its test, and the children are found by the mark.
    assert {row["pid"] for row in held_rows(env, tmp_path)} == set(children)
    assert set(children.values()) <= set(carrying(mark))
    return session, log, children


@pytest.mark.parametrize(
    ("how", "workers"),
    [
        ("SIGTERM", 2),
        ("SIGHUP", 2),
        ("Ctrl-C", 2),  # the control: SIGINT to the whole process group, as a terminal sends it
        ("SIGTERM", 0),  # the control: the same signal without xdist
    ],
    ids=["sigterm-xdist", "sighup-xdist", "ctrl-c-xdist", "sigterm-no-xdist"],
)
def test_a_signal_to_the_xdist_controller_ends_the_workers_as_ctrl_c_does(
    tmp_path: Path,
    env: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    session_mark: str,
    how: str,
    workers: int,
) -> None:
    """SIGTERM or SIGHUP to the controller alone: pytest exits 2, as without xdist, and only
    after every worker ended its test's child and released its ID: nothing of the session
    lives on, and status shows nothing held in the session's lock directory."""
    session, log, children = start_running_tests(tmp_path, env, session_mark, workers, started)
    if how == "Ctrl-C":
        os.killpg(session.pid, signal.SIGINT)
    else:
        session.send_signal(signal.Signals[how])
    code = session.wait(HUNG)
    output = log.read_text()
    assert code == pytest.ExitCode.INTERRUPTED, output
    # Nothing of the session lives once pytest has exited: workers, tests' children.
    assert carrying(session_mark) == [], output
    for child in children.values():
        assert f"stopped process {child}" in output, output  # ended by the sweep
    assert held_rows(env, tmp_path) == [], output


def test_xdist_workers_release_when_the_controller_is_killed(
    tmp_path: Path,
    env: dict[str, str],
    started: list[subprocess.Popen[bytes]],
    session_mark: str,
) -> None:
    """The controller gone (SIGKILL): execnet interrupts each worker (SIGINT), whose report
    to the controller then fails; the worker has ended its test's child and released its ID
    before, not in unconfigure, which pytest skips after that failure."""
    session, log, children = start_running_tests(tmp_path, env, session_mark, 2, started)
    session.kill()
    assert session.wait(HUNG) == -signal.SIGKILL
    poll_until(lambda: carrying(session_mark) == [], "every process of the session ended")
    output = log.read_text()
    for child in children.values():
        assert f"stopped process {child}" in output, output  # ended by the sweep
    assert held_rows(env, tmp_path) == [], output
