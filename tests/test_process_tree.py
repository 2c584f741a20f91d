"""Process-tree ownership, signals and PID 1, each against real processes.

The issue's promise: a domain ID is never handed to a test while any process of an
earlier test that used it is alive, and every way a test can end leaves a result file
that says how it ended. Every test tags the processes it starts with a variable of its
own, so "nothing survived" is checked across the whole machine, and teardown kills
whatever carries the tag whatever went wrong.
"""

from __future__ import annotations

import contextlib
import json
import os
import pty
import random
import re
import select
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities
from helpers.commands import CLI, run_cli, run_runner
from helpers.domains import HIGH_IDS, free_ids
from helpers.results import domain_of, load_result

HELPERS = Path(__file__).resolve().parent / "helpers"
DAEMON_TALKER = HELPERS / "daemon_talker.py"
TOKEN_LISTENER = HELPERS / "token_listener.py"
#: Upstream's RUNNER, from the ament_cmake_ros installed beside us.
UPSTREAM_RUNNER = capabilities.UPSTREAM_RUNNER_PATH
TAG_VAR = "ROS_ISOLATED_TEST_PROCESS_TREE_TAG"
POOL_VAR = "ROS_ISOLATED_TEST_DOMAINS"
WAIT_VAR = "ROS_ISOLATED_TEST_WAIT_TIMEOUT"
LEAKED_TOKEN = "leaked-talker"
#: Traps each forwarded signal, says which one came, exits 7.
TRAP_SCRIPT = (
    "trap 'echo INT > received; exit 7' INT; "
    "trap 'echo TERM > received; exit 7' TERM; "
    "trap 'echo HUP > received; exit 7' HUP; "
    "echo ready > ready; while :; do sleep 0.1; done"
)

needs_rclpy = capabilities.RCLPY.mark


# --- processes --------------------------------------------------------------------------


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


def finish(process: subprocess.Popen[bytes], timeout: float, log: Path) -> int:
    try:
        return process.wait(timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"still running after {timeout:g} s; output so far:\n{log.read_text()}")


# --- fixtures -----------------------------------------------------------------------------


@pytest.fixture
def tag() -> Iterator[str]:
    value = uuid.uuid4().hex
    yield value
    kill_tagged(value)


@pytest.fixture
def launcher(tag: str) -> Iterator[Launcher]:
    started = Launcher()
    yield started
    kill_tagged(tag)
    started.stop()


@pytest.fixture
def domain() -> int:
    """One free high ID: a pool of one, so the next run must get the very same ID.

    Picked at random: other test runs on this machine take the same IDs' ports.
    """
    return free_ids(1, random.sample(HIGH_IDS, len(HIGH_IDS)))[0]


@pytest.fixture
def tree_env(env: dict[str, str], tag: str, domain: int) -> dict[str, str]:
    """Runners wait a little: another test run may hold the ID's port for a moment."""
    return {**env, TAG_VAR: tag, POOL_VAR: str(domain), WAIT_VAR: "20"}


@pytest.fixture
def ros_env(tree_env: dict[str, str]) -> dict[str, str]:
    """Discovery on this host only: nothing from the network can pass for crosstalk."""
    return {**tree_env, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


@pytest.fixture(scope="module")
def pid_namespaces() -> None:
    capabilities.require(capabilities.UNSHARE)


# --- 1. a double-forked rclpy talker ------------------------------------------------------


def listener_report(stdout: str) -> dict[str, Any]:
    match = re.search(r"^RESULT (\{.*\})$", stdout, re.MULTILINE)
    assert match, f"the listener printed no RESULT line:\n{stdout}"
    report: dict[str, Any] = json.loads(match.group(1))
    return report


def ament_args(result: Path, command: Sequence[str]) -> list[str]:
    return [
        str(result),
        "--package-name",
        "pkg",
        "--generate-result-on-success",
        "--command",
        *command,
    ]


def talker_command(pid_file: Path, *options: str) -> list[str]:
    return [sys.executable, str(DAEMON_TALKER), str(pid_file), LEAKED_TOKEN, *options]


def listener_command(watch_pid: int) -> list[str]:
    return [sys.executable, str(TOKEN_LISTENER), "next-test", "--watch-pid", str(watch_pid)]


@pytest.mark.ros
@needs_rclpy
@pytest.mark.usefixtures("launcher")
def test_double_forked_talker_is_gone_before_the_next_test_gets_its_id(
    runner_script: str, ros_env: dict[str, str], domain: int, tmp_path: Path
) -> None:
    """The next test queues while the first runs, so it gets the ID the moment it is freed.

    The talker keeps publishing 1.5 s after SIGTERM: released any earlier, the ID
    would reach the listener while the talker still talks on it.
    """
    env = {**ros_env, WAIT_VAR: "30"}
    pid_file = tmp_path / "talker.pid"

    def next_test() -> subprocess.CompletedProcess[str]:
        talker = wait_for_pid(pid_file)
        command = listener_command(talker)
        return run_runner(runner_script, ament_args(tmp_path / "listener.xml", command), env)

    with ThreadPoolExecutor(1) as pool:
        queued = pool.submit(next_test)
        first = run_runner(
            runner_script,
            ament_args(tmp_path / "talker.xml", talker_command(pid_file, "--linger", "1.5")),
            env,
        )
        talker = read_pid(pid_file)
        survivor = describe([talker]) if talker is not None and alive(talker) else ""
        second = queued.result(timeout=120)

    assert talker is not None, first.stdout + first.stderr
    assert first.returncode == 0, first.stdout + first.stderr
    assert domain_of(first.stdout) == domain
    assert not survivor, f"the runner returned, the talker lives:\n{survivor}"
    assert re.search(rf"stopped process {talker}\b", first.stdout), first.stdout

    assert domain_of(second.stdout) == domain, second.stdout
    report = listener_report(second.stdout)
    assert not report["watched_alive_at_start"], "the ID was handed out while the talker lived"
    assert report["own"] > 0, "the listener never heard itself: DDS is broken, not isolated"
    assert report["foreign"] == {}, f"crosstalk from the earlier test: {report}"
    assert second.returncode == 0, second.stdout + second.stderr
    assert load_result(tmp_path / "listener.xml").only.outcome == "passed"


@pytest.fixture
def private_network() -> Iterator[list[str]]:
    """The prefix that runs a command in a network namespace of this test's own (lo up).

    Upstream takes the lowest ID whose port is free on the whole machine, and other ROS
    work here binds and frees low ports at any moment: only ports of our own make the
    next run get the same ID for sure.
    """
    capabilities.require(capabilities.NETWORK_NAMESPACES)
    name = f"rit-tree-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    subprocess.run(["ip", "netns", "add", name], check=True, capture_output=True, timeout=30)
    try:
        subprocess.run(
            ["ip", "-n", name, "link", "set", "lo", "up"],
            check=True,
            capture_output=True,
            timeout=30,
        )
        yield ["ip", "netns", "exec", name]
    finally:
        subprocess.run(
            ["ip", "netns", "delete", name], check=False, capture_output=True, timeout=30
        )


def run_upstream(
    prefix: Sequence[str], args: Sequence[str], env: Mapping[str, str]
) -> subprocess.CompletedProcess[str]:
    """Upstream's RUNNER as ctest calls it, inside ``prefix`` (a network namespace)."""
    return subprocess.run(
        [*prefix, sys.executable, "-u", str(UPSTREAM_RUNNER), *args],
        check=False,
        env=dict(env),
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.ros
@needs_rclpy
@pytest.mark.usefixtures("launcher")
def test_control_upstream_runner_hands_the_id_on_while_the_talker_still_talks(
    ros_env: dict[str, str], tmp_path: Path, private_network: list[str]
) -> None:
    """Proves the test above can fail: the same two tests under upstream's RUNNER."""
    capabilities.require(capabilities.UPSTREAM_RUNNER)
    env = {key: value for key, value in ros_env.items() if key not in (POOL_VAR, WAIT_VAR)}
    pid_file = tmp_path / "talker.pid"
    # Upstream reads the test's output until EOF: a daemon holding it would hang it.
    command = talker_command(pid_file, "--detach-stdio")
    first = run_upstream(private_network, ament_args(tmp_path / "talker.xml", command), env)
    assert first.returncode == 0, first.stdout + first.stderr
    leaked_on = domain_of(first.stdout)
    talker = read_pid(pid_file)
    assert talker is not None and alive(talker), "upstream's runner stopped the talker after all"
    assert f"ROS_DOMAIN_ID={leaked_on}".encode() in environ_of(talker)

    args = ament_args(tmp_path / "listener.xml", listener_command(talker))
    second = run_upstream(private_network, args, env)
    assert domain_of(second.stdout) == leaked_on, "upstream gave the listener another ID"
    report = listener_report(second.stdout)
    assert report["watched_alive_at_start"]
    assert report["own"] > 0, "the listener never heard itself: DDS is broken"
    assert report["foreign"].get(LEAKED_TOKEN, 0) > 0, f"no crosstalk heard: {report}"
    assert second.returncode != 0


# --- 2. the runner killed with SIGKILL ----------------------------------------------------


def test_orphans_of_a_killed_runner_keep_their_id_from_other_tests(
    tree_env: dict[str, str], domain: int, launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    script = "sleep 60 & echo $! > child.pid; echo $$ > main.pid; exec sleep 60"
    log = tmp_path / "runner.log"
    runner = launcher.start([CLI, "run", "--", "sh", "-c", script], tree_env, log, cwd=tmp_path)
    child = wait_for_pid(tmp_path / "child.pid", process=runner, log=log)
    wait_for_pid(tmp_path / "main.pid", process=runner, log=log)
    os.kill(runner.pid, signal.SIGKILL)
    runner.wait()
    assert alive(child), "nothing outlived the runner: the scenario did not happen"

    status = run_cli(["status", "--json"], tree_env)
    assert status.returncode == 0, status.stdout + status.stderr
    rows = json.loads(status.stdout)
    squatters = [(row["domain_id"], row.get("pid")) for row in rows if row["via"] == "environment"]
    assert (domain, child) in squatters, status.stdout

    refused = run_cli(["run", "--wait-timeout", "0", "--", "true"], tree_env, cwd=tmp_path)
    assert refused.returncode == 3, refused.stdout + refused.stderr
    assert "no free ROS_DOMAIN_ID" in refused.stderr
    # The refused reservation's scan wrote the orphan down in a block record: from then on
    # it is named once, as a survivor (issue 30, item 9), no longer as a squatter too.
    assert f"survivor pid {child}" in refused.stderr, refused.stderr
    assert f"squatter pid {child}" not in refused.stderr, refused.stderr

    kill_tagged(tag)
    assert not tagged(tag)
    granted = run_cli(["run", "--", "true"], tree_env, cwd=tmp_path)
    assert granted.returncode == 0, granted.stdout + granted.stderr
    assert domain_of(granted.stdout) == domain


# --- 3. signals ---------------------------------------------------------------------------


def interruption(result: Path) -> str:
    case = load_result(result).only
    assert case.outcome in ("failure", "error"), case
    return f"{case.message}\n{case.text}"


@pytest.mark.parametrize(
    "signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=lambda signum: signum.name
)
def test_signal_to_the_runner_reaches_the_test_and_is_reported(
    signum: signal.Signals, tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    result = tmp_path / "result.xml"
    args = [CLI, "run", "--junit-xml", str(result), "--", "sh", "-c", TRAP_SCRIPT]
    log = tmp_path / "runner.log"
    runner = launcher.start(args, tree_env, log, cwd=tmp_path)
    wait_for((tmp_path / "ready").exists, 30, "the test to start", runner, log)
    os.kill(runner.pid, signum)
    code = finish(runner, 15, log)

    received = tmp_path / "received"
    assert received.exists(), f"the test never got {signum.name}:\n{log.read_text()}"
    assert received.read_text().strip() == signum.name[3:], log.read_text()
    assert code == 128 + signum, log.read_text()
    message = interruption(result)
    assert "interrupted" in message and signum.name in message, message
    assert_no_survivors(tag)


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


def test_sigint_to_the_whole_process_group_leaves_nothing(
    tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    """Ctrl-C under colcon: the group gets SIGINT, background jobs of sh ignore it."""
    script = (
        "sleep 60 & echo $! > background.pid; setsid sleep 60 & echo $! > session.pid; "
        "echo ready > ready; wait"
    )
    result = tmp_path / "result.xml"
    args = [CLI, "run", "--kill-grace", "2", "--junit-xml", str(result), "--", "sh", "-c", script]
    log = tmp_path / "runner.log"
    runner = launcher.start(args, tree_env, log, cwd=tmp_path, start_new_session=True)
    wait_for((tmp_path / "ready").exists, 30, "the test to start", runner, log)
    leftovers = [wait_for_pid(tmp_path / "background.pid"), wait_for_pid(tmp_path / "session.pid")]
    os.killpg(runner.pid, signal.SIGINT)
    code = finish(runner, 20, log)

    assert code == 128 + signal.SIGINT, log.read_text()
    assert not any(alive(pid) for pid in leftovers), describe(leftovers)
    assert_no_survivors(tag)
    message = interruption(result)
    assert "interrupted" in message and "SIGINT" in message, message


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


# --- 4. a terminal's stdin ----------------------------------------------------------------


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


# --- 5. PID 1 of a container --------------------------------------------------------------


def in_pid_namespace(*args: str) -> list[str]:
    return ["unshare", "--pid", "--fork", "--mount-proc", CLI, *args]


@pytest.mark.usefixtures("pid_namespaces")
def test_pid_1_reaps_orphaned_grandchildren(tree_env: dict[str, str], tmp_path: Path) -> None:
    script = (
        # Orphans that live until told to go: their parents have exited, so they are
        # PID 1's now; once gone (kill -0 fails for a reaped one, not for a zombie), no
        # zombie may be left. Order of events only: no sleep decides anything.
        "for i in 1 2 3 4 5; do sh -c 'while [ ! -e go ]; do sleep 0.05; done & "
        "echo $! >> orphans'; done; "
        "adopted=0; for p in $(cat orphans); do "
        '[ "$(ps -o ppid= -p $p | tr -d " ")" = 1 ] && adopted=$((adopted+1)); done; '
        "echo adopted=$adopted; touch go; "
        "n=0; for p in $(cat orphans); do "
        "while kill -0 $p 2>/dev/null && [ $n -lt 600 ]; do sleep 0.1; n=$((n+1)); done; done; "
        "echo zombies=$(ps -eo stat= | grep -c '^Z'); exit 42"
    )
    result = tmp_path / "result.xml"
    proc = subprocess.run(
        in_pid_namespace("run", "--junit-xml", str(result), "--", "sh", "-c", script),
        env=tree_env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    output = proc.stdout + proc.stderr
    assert "adopted=5" in proc.stdout, f"the orphans were not the runner's to reap:\n{output}"
    assert "zombies=0" in proc.stdout, output
    assert proc.returncode == 42, output
    assert "exited with code 42" in interruption(result)


@pytest.mark.usefixtures("pid_namespaces")
def test_pid_1_passes_sigterm_on_and_ends_within_the_grace(
    tree_env: dict[str, str], launcher: Launcher, tag: str, tmp_path: Path
) -> None:
    # Far longer than the test takes to end on SIGTERM: a PID 1 that sat out the grace
    # (instead of ending with its test) would still run when finish() gives up.
    grace = 300.0
    result = tmp_path / "result.xml"
    args = in_pid_namespace(
        "run", "--kill-grace", f"{grace:g}", "--junit-xml", str(result), "--", "sh", "-c"
    )
    log = tmp_path / "runner.log"
    unshare = launcher.start([*args, TRAP_SCRIPT], tree_env, log, cwd=tmp_path)
    wait_for((tmp_path / "ready").exists, 30, "the test to start", unshare, log)
    (runner,) = children_of(unshare.pid)
    assert alive(runner)
    os.kill(runner, signal.SIGTERM)
    code = finish(unshare, 60, log)

    assert (tmp_path / "received").read_text().strip() == "TERM", log.read_text()
    assert code == 128 + signal.SIGTERM, log.read_text()
    assert_no_survivors(tag)
    message = interruption(result)
    assert "interrupted" in message and "SIGTERM" in message, message
