"""Acceptance: the runner under ctest and colcon, a pool shared by waiting runners, LRU IDs.

- A ctest TIMEOUT kills the runner's whole tree (a double-forked daemon included, kept in
  the tree by the subreaper), ctest is not held by the output pipe, and the placeholder
  result says the test most likely timed out.
- Ctrl-C as a terminal delivers it (SIGINT to colcon's whole process group) leaves no
  process of the run and a result file per test saying it was interrupted.
- Six tests of the example package share a pool of two IDs, never two on one ID at once.
- A runner facing a full pool waits, first come first served, printing who holds the pool,
  up to --wait-timeout / ROS_ISOLATED_TEST_WAIT_TIMEOUT, then fails with exit 3.
- Among free IDs the one released longest ago is taken (never released counts as oldest).

Every process started here carries this test's lock directory in its environment; the
``marker`` fixture kills whatever still carries it when the test ends.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import random
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import pytest
from helpers import capabilities
from helpers.commands import CLI, run_cli, run_runner
from helpers.results import ResultSummary, load_result
from helpers.workspace import CrosstalkBuilds, crosstalk_workspace

from ros_isolated_test.domain_coordinator import (
    LOCK_DIR_ENV,
    POOL_ENV,
    participants,
    port_guard,
    squatters,
)
from ros_isolated_test.domain_coordinator.pool import HIGHEST_VALID_ID
from ros_isolated_test.runner.settings import WAIT_TIMEOUT_ENV

if TYPE_CHECKING:  # annotations only; the module is loaded by path below
    pass

T = TypeVar("T")

PLACEHOLDER = "most likely timed out"
#: A waiter at the head of the queue looks every 0.05 s and its test starts in under a
#: second even on a loaded machine; a waiter that slept between looks would miss this.
PROMPT_S = 6.0
WAITING = re.compile(r"^.*waiting for a free ROS_DOMAIN_ID.*$", re.MULTILINE)
DOMAIN_LINE = re.compile(r"Running with ROS_DOMAIN_ID (\d+)")


ws = crosstalk_workspace()

needs_colcon = capabilities.COLCON.mark


# --- processes -----------------------------------------------------------------------------


def _stat(pid: int) -> tuple[str, int] | None:
    """State letter and parent PID of ``pid``, or None when it is gone."""
    try:
        data = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return None
    fields = data[data.rfind(b")") + 2 :].split()
    return fields[0].decode(), int(fields[1])


def _alive(pid: int) -> bool:
    """Running or stopped; a zombie is dead (PID 1 here may be slow to reap it)."""
    stat = _stat(pid)
    return stat is not None and stat[0] not in ("Z", "X")


def _processes_with(entry: bytes) -> dict[int, str]:
    """Live processes whose environment holds ``entry``, with their command lines."""
    found: dict[int, str] = {}
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) == os.getpid():
            continue
        try:
            environ = Path(f"/proc/{name}/environ").read_bytes()
            cmdline = Path(f"/proc/{name}/cmdline").read_bytes()
        except OSError:
            continue
        if entry in environ.split(b"\0") and _alive(int(name)):
            found[int(name)] = cmdline.replace(b"\0", b" ").decode("utf-8", "replace").strip()
    return found


def _has_domain_id(pid: int) -> bool:
    try:
        environ = Path(f"/proc/{pid}/environ").read_bytes()
    except OSError:
        return False
    return any(item.startswith(b"ROS_DOMAIN_ID=") for item in environ.split(b"\0"))


def _poll(check: Callable[[], T], timeout: float, what: str, interval: float = 0.05) -> T:
    """``check()`` once it is truthy; fails the test after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"{what}: not within {timeout:g} s")
        time.sleep(interval)


@pytest.fixture
def marker(lock_dir: Path) -> Iterator[bytes]:
    """The environment entry of every process this test starts; leftovers die at the end."""
    entry = f"{LOCK_DIR_ENV}={lock_dir}".encode()
    yield entry
    for pid in _processes_with(entry):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGKILL)


def _free_ids(count: int) -> list[int]:
    """IDs nothing on this machine uses now, at random: other sessions may test beside us."""
    # A DDS participant elsewhere (another session's rclpy test) keeps an ID from us too.
    busy = set(squatters.scan()) | set(participants.bound_domains())
    free = [
        domain_id
        for domain_id in range(102, HIGHEST_VALID_ID + 1)
        if domain_id not in busy and not port_guard.port_is_taken(domain_id)
    ]
    assert len(free) >= count, f"only {len(free)} free domain IDs in 102-{HIGHEST_VALID_ID}"
    return random.sample(free, count)


# --- ctest TIMEOUT -------------------------------------------------------------------------

#: A test that leaves a double-forked daemon holding its stdout, then sleeps past TIMEOUT.
LEAKY = """\
import os, sys, time
from pathlib import Path

pids = Path(sys.argv[1])


def note(name):
    temp = pids / f".{name}"
    temp.write_text(str(os.getpid()))
    temp.rename(pids / name)


if os.fork() == 0:
    os.setsid()
    if os.fork() == 0:
        note("daemon")
        print("daemon running", flush=True)
        time.sleep(300)
    os._exit(0)
os.wait()
note("main")
print("main sleeping", flush=True)
time.sleep(60)
"""

CMAKE = """\
cmake_minimum_required(VERSION 3.16)
project(timeout_probe NONE)
enable_testing()
add_test(NAME t COMMAND [==[{python}]==] -u [==[{runner}]==] [==[{result}]==]
  --package-name p --command [==[{python}]==] [==[{script}]==] [==[{pids}]==])
set_tests_properties(t PROPERTIES TIMEOUT 6)
"""


@capabilities.CTEST
def test_ctest_timeout_leaves_nothing_running_and_the_placeholder_says_timeout(
    tmp_path: Path, env: dict[str, str], runner_script: str, marker: bytes
) -> None:
    pids = tmp_path / "pids"
    pids.mkdir()
    script = tmp_path / "leaky.py"
    script.write_text(LEAKY)
    result = tmp_path / "results" / "t.xml"
    source, build = tmp_path / "src", tmp_path / "build"
    source.mkdir()
    build.mkdir()
    (source / "CMakeLists.txt").write_text(
        CMAKE.format(
            python=sys.executable, runner=runner_script, result=result, script=script, pids=pids
        )
    )
    configure = subprocess.run(
        ["cmake", str(source)], cwd=build, env=env, capture_output=True, text=True, check=False
    )
    assert configure.returncode == 0, configure.stdout + configure.stderr

    log = tmp_path / "ctest.log"
    with log.open("wb") as out:
        ctest = subprocess.Popen(
            ["ctest", "--output-on-failure"],
            cwd=build,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        # The daemon notes its PID on its own time: main only waits for its parent.
        _poll(
            lambda: (pids / "main").exists() and (pids / "daemon").exists(),
            10,
            "the test wrote no PIDs",
        )
        main = int((pids / "main").read_text())
        daemon = int((pids / "daemon").read_text())
        main_stat, daemon_stat = _stat(main), _stat(daemon)
        assert main_stat is not None and daemon_stat is not None, "the test ended too early"
        runner = main_stat[1]
        assert "run_test_isolated.py" in Path(f"/proc/{runner}/cmdline").read_text()
        assert daemon_stat[1] == runner, (
            f"the double-forked daemon's parent is {daemon_stat[1]}, not the runner {runner}: "
            "no subreaper, ctest's timeout kill cannot find it"
        )
        # The daemon sleeps 300 s holding ctest's output pipe: a ctest that ends long
        # before that was not held by it (the TIMEOUT is 6 s, long enough to read its PIDs).
        try:
            returncode = ctest.wait(timeout=120)
        except subprocess.TimeoutExpired:
            pytest.fail(
                "ctest still runs 120 s after a 6 s TIMEOUT: something holds its output pipe\n"
                + log.read_text(errors="replace")
            )
    finally:
        if ctest.poll() is None:
            ctest.kill()
            ctest.wait()
    output = log.read_text(errors="replace")

    assert returncode != 0, output
    assert "Timeout" in output, output
    _poll(
        lambda: not any(_alive(pid) for pid in (runner, main, daemon)),
        30,
        f"runner {runner}, test {main} or daemon {daemon} survived the timeout",
    )
    assert not _processes_with(marker), _processes_with(marker)
    case = load_result(result).only
    assert case.outcome == "error", case
    assert PLACEHOLDER in case.text, case.text


# --- colcon test of the example package ----------------------------------------------------


@pytest.fixture
def built(crosstalk_builds: CrosstalkBuilds) -> Path:
    """The session's build of the example package with our runner, no earlier results."""
    return crosstalk_builds.fresh("isolated")


def _result_path(base: Path, test: str) -> Path:
    package: str = ws.PACKAGE
    return base / "build" / package / "test_results" / package / f"{test}.xml"


@contextlib.contextmanager
def _colcon_test(base: Path, extra_env: dict[str, str]) -> Iterator[subprocess.Popen[bytes]]:
    """``colcon test --ctest-args -j6`` in a process group of its own, as a terminal's job."""
    env = ws.colcon_env()
    env.update(extra_env)
    # As in a terminal: a suite started in the background (``cmd &`` in a script) ignores
    # SIGINT, and exec keeps an ignored signal: colcon would never see the Ctrl-C. A handler
    # of ours becomes the default in the child.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with (base / "colcon-test.log").open("wb") as out:
            process = subprocess.Popen(
                ["colcon", "--log-base", str(base / "log"), "test", *ws._common(base),
                 "--ctest-args", "-j6"],
                cwd=base.parent,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )  # fmt: skip
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        yield process
    finally:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=10)


def _says_interrupted(summary: ResultSummary) -> bool:
    case = summary.only
    said = " ".join(
        (case.message, summary.properties.get("exit", ""),
         summary.properties.get("signal_received", ""))
    )  # fmt: skip
    return "interrupted" in said and "SIGINT" in said


@pytest.mark.colcon
@needs_colcon
@pytest.mark.parametrize(
    "pool_size", [None, 2], ids=["all-six-running", "pool-of-two-four-waiting"]
)
def test_ctrl_c_under_colcon_leaves_nothing_and_says_interrupted(
    built: Path, lock_dir: Path, marker: bytes, pool_size: int | None
) -> None:
    """With a pool of two, four runners are queued for an ID when Ctrl-C comes."""
    _registered_runner, tokens = ws.registered_tests(built)
    tests = sorted(tokens)
    assert len(tests) == 6
    for name in tests:
        with contextlib.suppress(FileNotFoundError):
            _result_path(built, name).unlink()
    extra = {"CROSSTALK_RECORD_DIR": str(built / "records")}
    if pool_size is not None:
        extra[POOL_ENV] = ",".join(str(i) for i in _free_ids(pool_size))
    queue = lock_dir / "queue"

    talkers_seen: set[int] = set()

    def all_started() -> bool:
        """Six talkers seen; with a small pool, those running and the rest queued."""
        processes = _processes_with(marker)
        runners = {pid for pid, cmd in processes.items() if "run_test_isolated.py" in cmd}
        talkers = {pid for pid, cmd in processes.items() if "token_talker.py" in cmd} - runners
        talkers_seen.update(talkers)
        if pool_size is None:
            return len(talkers_seen) == 6
        # A ticket in the queue is the only sign, seen from outside, that a runner under
        # ctest is waiting for an ID (its output goes to ctest, not to us).
        queued = len(list(queue.glob("*.ticket"))) if queue.is_dir() else 0
        return len(runners) == 6 and len(talkers) == pool_size and queued == 6 - pool_size

    with _colcon_test(built, extra) as colcon:
        _poll(all_started, 60, "the six tests did not all start", interval=0.1)
        assert all(_has_domain_id(pid) for pid in talkers_seen if _alive(pid))
        os.killpg(colcon.pid, signal.SIGINT)
        deadline = time.monotonic() + 20
        try:
            returncode = colcon.wait(timeout=20)
        except subprocess.TimeoutExpired:
            pytest.fail("colcon still runs 20 s after Ctrl-C")
        survivors = _processes_with(marker)
        while survivors and time.monotonic() < deadline:
            time.sleep(0.1)
            survivors = _processes_with(marker)
        described = {
            pid: f"{cmd} [{'with' if _has_domain_id(pid) else 'without'} ROS_DOMAIN_ID]"
            for pid, cmd in survivors.items()
        }
        assert not described, f"survived Ctrl-C by 20 s: {described}"
    log = (built / "colcon-test.log").read_text(errors="replace")
    assert returncode != 0, log

    verdicts: dict[str, str] = {}
    for name in tests:
        summary = load_result(_result_path(built, name))
        exit_reason = summary.properties.get("exit", "")
        if PLACEHOLDER in summary.only.text:
            verdicts[name] = "bare placeholder (says 'most likely timed out')"
        elif not (_says_interrupted(summary) or exit_reason.startswith("exited with code")):
            verdicts[name] = f"neither interrupted nor finished: {exit_reason!r}"
    assert not verdicts, f"result files after Ctrl-C: {verdicts}\n{log}"


@pytest.mark.colcon
@needs_colcon
@pytest.mark.usefixtures("marker")
def test_six_tests_on_a_pool_of_two_pass_one_per_id_at_a_time(
    crosstalk_builds: CrosstalkBuilds, monkeypatch: pytest.MonkeyPatch
) -> None:
    pool = _free_ids(2)
    monkeypatch.setenv(POOL_ENV, ",".join(str(i) for i in pool))
    run = crosstalk_builds.test("isolated")

    records = [case.record for case in run.cases]
    assert len(records) == 6 and None not in records, run.test_output
    failed = {r.token: r.foreign or "never heard itself" for r in records if r and not r.passed}
    assert not failed, f"{failed}\n{run.test_output}"
    used = {r.domain_id for r in records if r}
    assert used <= {str(i) for i in pool}, f"IDs {used} outside the pool {pool}"
    for domain_id in used:
        spans = sorted((r.start, r.end, r.token) for r in records if r and r.domain_id == domain_id)
        for (_s1, end, first), (start, _e2, second) in itertools.pairwise(spans):
            assert end <= start, f"{first} and {second} overlapped on ID {domain_id}: {spans}"
    assert run.result.returncode == 0, run.result.line
    assert (run.result.errors, run.result.failures) == (0, 0), run.result.line
    assert run.result.tests >= 6, run.result.line


# --- waiting for an ID ---------------------------------------------------------------------

#: The tenants' test: record when it got which ID, then hold it until GO exists ("-": not).
TENANT = """\
import os, sys, time
from pathlib import Path

got, go = Path(sys.argv[1]), sys.argv[2]
temp = got.with_name(got.name + ".tmp")
temp.write_text(f"{time.time()} {os.environ['ROS_DOMAIN_ID']}")
temp.rename(got)
deadline = time.monotonic() + 60
while go != "-" and not Path(go).exists() and time.monotonic() < deadline:
    time.sleep(0.02)
"""


@dataclass
class Tenant:
    """A background ``ros-isolated-test run`` of TENANT."""

    process: subprocess.Popen[bytes]
    log: Path
    got: Path
    go: Path

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def got_id(self) -> tuple[float, int] | None:
        """When its test started and on which ID, once it has."""
        if not self.got.exists():
            return None
        at, domain_id = self.got.read_text().split()
        return float(at), int(domain_id)

    def waiting(self) -> bool:
        return bool(WAITING.search(self.output()))

    def release(self) -> int:
        """Let its test end; returns the runner's exit code."""
        self.go.touch()
        return self.process.wait(timeout=30)


class Tenants:
    """Starts tenants in one folder; whatever is left is killed at the end."""

    def __init__(self, tmp_path: Path, env: dict[str, str]) -> None:
        self.dir = tmp_path / "tenants"
        self.dir.mkdir()
        self.script = self.dir / "tenant.py"
        self.script.write_text(TENANT)
        self.env = env
        self.started: list[Tenant] = []

    def start(self, *options: str, hold: bool = True) -> Tenant:
        index = len(self.started)
        log, got, go = (self.dir / f"{index}.{kind}" for kind in ("log", "got", "go"))
        with log.open("wb") as out:
            process = subprocess.Popen(
                [CLI, "run", *options, "--", sys.executable, str(self.script), str(got),
                 str(go) if hold else "-"],
                env=self.env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
            )  # fmt: skip
        tenant = Tenant(process, log, got, go)
        self.started.append(tenant)
        return tenant

    def holding(self, *options: str) -> Tenant:
        """A tenant that holds an ID, once it does."""
        tenant = self.start(*options)
        _poll(
            lambda: tenant.got_id() or tenant.process.poll() is not None,
            30,
            "the tenant got no ID",
        )
        assert tenant.got_id(), tenant.output()
        return tenant

    def queued(self, *options: str, hold: bool = False) -> Tenant:
        """A tenant that waits for an ID, once it says so."""
        tenant = self.start(*options, hold=hold)
        _poll(
            lambda: tenant.waiting() or tenant.process.poll() is not None,
            30,
            "the tenant did not start waiting",
        )
        assert tenant.waiting(), tenant.output()
        return tenant

    def stop(self) -> None:
        for tenant in self.started:
            if tenant.process.poll() is None:
                tenant.process.kill()
            tenant.process.wait()


@pytest.fixture
def tenants(tmp_path: Path, env: dict[str, str], marker: bytes) -> Iterator[Tenants]:
    crowd = Tenants(tmp_path, env)
    yield crowd
    crowd.stop()


@pytest.fixture
def pool_of_one(env: dict[str, str]) -> int:
    (domain_id,) = _free_ids(1)
    env[POOL_ENV] = str(domain_id)
    return domain_id


def _hold_with_sleep(env: dict[str, str], log: Path) -> subprocess.Popen[bytes]:
    """``ros-isolated-test run -- sleep 60``, once ``status`` names it as the holder."""
    with log.open("wb") as out:
        holder = subprocess.Popen(
            [CLI, "run", "--", "sleep", "60"],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
        )

    def held() -> bool:
        assert holder.poll() is None, log.read_text()
        status = run_cli(["status"], env)
        return f" {holder.pid} " in status.stdout

    _poll(held, 30, "the holder did not get the ID", interval=0.1)
    return holder


@pytest.mark.parametrize(
    ("how", "limit"),
    [("option", 1.5), ("env", 1.0), ("ctest-runner", 1.0)],
)
def test_a_full_pool_is_waited_for_then_fails_with_exit_3_and_a_result(
    tmp_path: Path,
    env: dict[str, str],
    marker: bytes,
    pool_of_one: int,
    runner_script: str,
    how: str,
    limit: float,
) -> None:
    holder = _hold_with_sleep(env, tmp_path / "holder.log")
    result = tmp_path / "out" / "waiter.xml"
    try:
        started = time.monotonic()
        if how == "option":
            proc = run_cli(["run", "--wait-timeout", str(limit), "--junit-xml", str(result),
                            "--", "true"], env)  # fmt: skip
        elif how == "env":
            proc = run_cli(
                ["run", "--junit-xml", str(result), "--", "true"],
                {**env, WAIT_TIMEOUT_ENV: str(limit)},
            )
        else:
            proc = run_runner(
                runner_script,
                [str(result), "--package-name", "p", "--command", "true"],
                {**env, WAIT_TIMEOUT_ENV: str(limit)},
            )
        elapsed = time.monotonic() - started
        # It gave up by itself: the holder (sleep 60) still held the ID when it failed.
        holder_held_on = holder.poll() is None
    finally:
        holder.terminate()
        holder.wait(timeout=30)

    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert elapsed >= limit, f"failed after {elapsed:.1f} s, before its limit {limit}"
    assert holder_held_on, "the waiter failed only after the holder had ended"
    waiting = WAITING.findall(proc.stdout)
    assert waiting, proc.stdout
    assert f"{pool_of_one}: pid {holder.pid} " in waiting[0], waiting[0]
    assert "sleep 60" in waiting[0], waiting[0]
    assert "after waiting" in proc.stderr and "no free ROS_DOMAIN_ID" in proc.stderr, proc.stderr
    summary = load_result(result)
    assert summary.only.outcome == "error", summary
    assert "after waiting" in summary.only.message, summary.only.message
    assert "no free ROS_DOMAIN_ID" in summary.only.message, summary.only.message
    assert summary.properties.get("exit") == "not run", summary.properties


@pytest.mark.parametrize("value", ["soon", "-1", "nan"])
@pytest.mark.parametrize("entry", ["run", "ctest-runner"])
def test_an_invalid_wait_timeout_in_the_environment_is_a_usage_error(
    tmp_path: Path,
    env: dict[str, str],
    marker: bytes,
    pool_of_one: int,
    runner_script: str,
    entry: str,
    value: str,
) -> None:
    result = tmp_path / "out" / "r.xml"
    bad = {**env, WAIT_TIMEOUT_ENV: value}
    if entry == "run":
        proc = run_cli(["run", "--junit-xml", str(result), "--", "true"], bad)
    else:
        proc = run_runner(
            runner_script, [str(result), "--package-name", "p", "--command", "true"], bad
        )
    said = proc.stdout + proc.stderr
    assert proc.returncode == 2, f"{WAIT_TIMEOUT_ENV}={value!r} accepted:\n{said}"
    assert "wait-timeout" in said.lower() or WAIT_TIMEOUT_ENV in said, said
    assert "Running with ROS_DOMAIN_ID" not in said, said


def test_the_waiting_line_names_the_holder_not_its_test_as_a_squatter(
    tmp_path: Path, env: dict[str, str], marker: bytes, pool_of_one: int
) -> None:
    """The holder's own test carries the ID legitimately; calling it a squatter misleads."""
    holder = _hold_with_sleep(env, tmp_path / "holder.log")
    try:
        proc = run_cli(["run", "--wait-timeout", "0.3", "--", "true"], env)
    finally:
        holder.terminate()
        holder.wait(timeout=30)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    (line, *_) = WAITING.findall(proc.stdout)
    assert f"pid {holder.pid} " in line, line
    assert "squatter" not in line, line


def test_the_waiting_line_says_a_free_id_goes_to_an_earlier_waiter_first(
    tenants: Tenants, env: dict[str, str], pool_of_one: int
) -> None:
    """An ID is free but an earlier waiter is to have it: the line says so, not "in use".

    The earlier waiter is stopped (SIGSTOP) once the ID comes free, so the newcomer waits
    behind it with the ID free for as long as the test needs. The control is the
    earlier waiter's own line, written while the pool really was in use.
    """
    first = tenants.holding()
    second = tenants.queued("--wait-timeout", "300", hold=True)
    os.kill(second.process.pid, signal.SIGSTOP)
    try:
        assert first.release() == 0, first.output()
        third = tenants.queued("--wait-timeout", "300")
    finally:
        os.kill(second.process.pid, signal.SIGCONT)
    (control, *_) = WAITING.findall(second.output())
    assert "all 1 IDs of the pool are in use" in control, control
    (line, *_) = WAITING.findall(third.output())
    assert "1 runner(s) ahead" in line, line
    assert "1 of 1 IDs free, for earlier waiters first" in line, line
    # And the order holds: the earlier waiter has the ID before the newcomer.
    _poll(second.got_id, 60, "the earlier waiter did not get the free ID")
    assert third.got_id() is None, third.output()
    assert second.release() == 0, second.output()
    _poll(third.got_id, 60, "the newcomer did not get the ID after the earlier waiter")
    assert third.release() == 0, third.output()


def test_the_waiting_line_is_refreshed_with_the_new_holder(
    tenants: Tenants, env: dict[str, str], pool_of_one: int
) -> None:
    """The holder changes while the waiter waits; its next line (every 10 s) says so.

    It waits 16 s: lines at 0 and 10 s, the second 6 s before it gives up (not 1 s).
    """
    first = tenants.holding()
    second = tenants.queued("--wait-timeout", "60", hold=True)
    waiter = tenants.queued("--wait-timeout", "16")
    first.release()
    _poll(second.got_id, 60, "the first waiter did not get the ID when it came free")
    code = waiter.process.wait(timeout=120)
    lines = WAITING.findall(waiter.output())
    assert code == 3, waiter.output()
    assert len(lines) >= 2, waiter.output()
    assert f"pid {first.process.pid} " in lines[0], lines[0]
    assert "1 runner(s) ahead" in lines[0], lines[0]
    assert f"pid {second.process.pid} " in lines[-1], lines[-1]
    assert f"pid {first.process.pid} " not in lines[-1], lines[-1]
    assert "0 runner(s) ahead" in lines[-1], lines[-1]
    assert second.release() == 0, second.output()


def test_a_waiter_gets_the_id_as_soon_as_the_holder_ends(
    tenants: Tenants, pool_of_one: int
) -> None:
    holder = tenants.holding()
    waiter = tenants.queued("--wait-timeout", "60")
    assert waiter.got_id() is None
    released = time.time()
    assert holder.release() == 0, holder.output()
    got = _poll(waiter.got_id, 60, "the waiter did not get the ID")
    assert got is not None
    at, domain_id = got
    assert domain_id == pool_of_one
    assert waiter.process.wait(timeout=30) == 0, waiter.output()
    assert released <= at, "the waiter's test started before the holder let go"
    waited = at - released
    assert waited < PROMPT_S, f"the waiter's test started {waited:.2f} s after release"


def test_waiters_get_the_id_in_arrival_order(tenants: Tenants, pool_of_one: int) -> None:
    holder = tenants.holding()
    waiters = [tenants.queued("--wait-timeout", "60") for _ in range(4)]
    assert holder.release() == 0, holder.output()
    for waiter in waiters:
        assert waiter.process.wait(timeout=30) == 0, waiter.output()
    got = [waiter.got_id() for waiter in waiters]
    assert None not in got
    order = sorted(range(4), key=lambda index: got[index] or (0.0, 0))
    assert order == [0, 1, 2, 3], f"arrival order 0-3 got the ID in order {order}: {got}"


# --- least recently used -------------------------------------------------------------------


def _run_once(env: dict[str, str]) -> int:
    proc = run_cli(["run", "--", "true"], env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    match = DOMAIN_LINE.search(proc.stdout)
    assert match, proc.stdout
    return int(match.group(1))


def test_the_id_released_longest_ago_is_taken_first(tenants: Tenants, env: dict[str, str]) -> None:
    a, b, c = _free_ids(3)
    env[POOL_ENV] = f"{a},{b},{c}"
    # Never released beats released: one after another, the three rotate in pool order.
    assert [_run_once(env) for _ in range(3)] == [a, b, c]
    holders: dict[int, Tenant] = {}
    for _ in range(3):
        tenant = tenants.holding()
        got = tenant.got_id()
        assert got is not None
        holders[got[1]] = tenant
    assert sorted(holders) == sorted((a, b, c))
    release_order = (b, c, a)  # neither the pool's order nor the previous rotation
    for domain_id in release_order:
        assert holders[domain_id].release() == 0, holders[domain_id].output()
    assert [_run_once(env) for _ in range(3)] == list(release_order)
