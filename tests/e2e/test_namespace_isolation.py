"""Namespace isolation end to end: each test on a network, a /dev/shm and IPC of its own.

Real runners, real namespaces, real rclpy over Fast DDS, across the tool: ``run``, the
ctest RUNNER and the pytest plugin. Each isolated case has its control beside it, which
must show the collision without namespaces: two servers on one fixed port collide in
domain mode, two SHM-only probes on one domain hear each other with isolation disabled,
and the runner refuses or falls back only where user namespaces are really forbidden
(``user.max_user_namespaces=0`` in a user namespace of the test's own, the host
untouched; a real seccomp filter). What the test itself sees of its namespaces is in
``tests/unit/process/test_namespace.py``, why a host refuses them in
``test_namespace_diagnosis.py`` there. Events are ordered by rendezvous files, never by
clocks.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities
from helpers.commands import (
    CLI,
    ERROR_PREFIX,
    HUNG,
    REPO,
    ament_args,
    run_cli,
    run_process,
    run_runner,
    start_cli,
    the_error_line,
)
from helpers.namespaces import (
    ISOLATION,
    LOOK,
    NAMESPACES,
    private_shm_name,
    seccomp_prefix,
    seen,
    user_namespace_prefix,
)
from helpers.processes import carrying, wait_for
from helpers.results import domain_of, load_result

pytestmark = [capabilities.UNSHARE.mark]

HELPERS = REPO / "tests" / "helpers"
CROWD_PROBE = HELPERS / "crowd_probe.py"
DAEMON_TALKER = HELPERS / "daemon_talker.py"
TAG_VAR = "ROS_ISOLATED_TEST_NAMESPACE_TAG"
NOT_RESERVED = "is not reserved (no ID of the pool is free)"
WAITING = "waiting for a free ROS_DOMAIN_ID"

#: A test serving on one fixed port: ``NAME PORT FOLDER OTHER``. It binds, says so in
#: FOLDER, holds the port until OTHER has tried its own bind (so the two overlap), then
#: connects to the port and must be answered by itself. Exit 1: the port was taken.
SERVE = r"""
import pathlib, socket, sys, time
name, port, folder, other = sys.argv[1], int(sys.argv[2]), pathlib.Path(sys.argv[3]), sys.argv[4]
server = socket.socket()
# A rerun within a minute must not meet the TIME_WAIT of the last one: only a holder counts.
server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
try:
    # Both calls may refuse: with SO_REUSEADDR two sockets can bind while neither listens.
    server.bind(("127.0.0.1", port))
    server.listen(1)
except OSError as error:
    (folder / f"{name}.refused").write_text(str(error))
    print(f"{name}: cannot serve on {port}: {error}", flush=True)
    sys.exit(1)
(folder / f"{name}.bound").write_text("")
stop = time.monotonic() + 60  # only stops a hang: the other test never started
while not any((folder / f"{other}.{how}").exists() for how in ("bound", "refused")):
    if time.monotonic() > stop:
        sys.exit(f"{name}: {other} never tried to serve")
    time.sleep(0.01)
client = socket.create_connection(("127.0.0.1", port))
connection, _peer = server.accept()
connection.sendall(name.encode())
connection.close()
heard = client.recv(64).decode()
print(f"{name}: served on {port}, answered by {heard!r}", flush=True)
sys.exit(0 if heard == name else 1)
"""


def free_port() -> int:
    """A TCP port free on this host now: the "fixed" port both servers are written for."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def reports(output: str) -> list[dict[str, Any]]:
    """Every ``RESULT {json}`` line a crowd probe printed."""
    return [
        json.loads(line[len("RESULT ") :])
        for line in output.splitlines()
        if line.startswith("RESULT ")
    ]


@pytest.fixture
def shm_name() -> Iterator[str]:
    """A file name the test writes into its /dev/shm; removed from the host's if it got there."""
    with private_shm_name() as name:
        yield name


# --- 1. one fixed port, two tests -------------------------------------------------------


def serve_twice(
    env: dict[str, str], tmp_path: Path, isolation: str, started: list[subprocess.Popen[bytes]]
) -> list[tuple[int, str]]:
    """Two tests serving on one fixed port, started at once: (exit code, output) each."""
    port = free_port()
    folder = tmp_path / "rendezvous"
    folder.mkdir()
    runners = []
    for name, other in (("alpha", "bravo"), ("bravo", "alpha")):
        args = ["run", "--isolation", isolation, "--junit-xml", str(tmp_path / f"{name}.xml"),
                "--", sys.executable, "-c", SERVE, name, str(port), str(folder), other]  # fmt: skip
        runners.append((start_cli(args, env, tmp_path / f"{name}.log", started), name))
    ended = []
    for process, name in runners:
        code = process.wait(HUNG)
        ended.append((code, (tmp_path / f"{name}.log").read_text()))
    return ended


def test_two_tests_serve_on_one_fixed_port_at_once_in_namespaces(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    ended = serve_twice(env, tmp_path, "namespace", started)
    for code, output in ended:
        assert code == 0, output
        assert "answered by" in output and NAMESPACES in output, output
    for name in ("alpha", "bravo"):
        assert load_result(tmp_path / f"{name}.xml").only.outcome == "passed"


def test_control_two_tests_on_one_fixed_port_collide_in_domain_mode(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """Without this collision the test above would prove nothing: it must keep failing."""
    ended = serve_twice(env, tmp_path, "domain", started)
    codes = sorted(code for code, _output in ended)
    outputs = "\n".join(output for _code, output in ended)
    assert codes == [0, 1], outputs
    assert "Address already in use" in outputs, outputs


# --- 2. six rclpy probes over shared memory, a pool of one ID -----------------------------


#: The range under which shared memory crosses network namespaces (measured: with Fast DDS
#: over SHM only, LOCALHOST discovers nobody in another network namespace, SYSTEM_DEFAULT
#: and SUBNET do, through a common /dev/shm). Namespace mode refuses SUBNET.
SHM_RANGE = "SYSTEM_DEFAULT"


def shm_env(env: dict[str, str]) -> dict[str, str]:
    """Fast DDS over shared memory only."""
    return {**env, "FASTDDS_BUILTIN_TRANSPORTS": "SHM"}


@pytest.mark.ros
@capabilities.RCLPY.mark
def test_six_shm_probes_on_a_pool_of_one_id_all_pass_at_once_in_namespaces(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """All six talk at the same moment (each waits until all six are up): none waited.

    With one ID, domain mode would hold five back until the first ended, and the first
    would never see its peers up; here each runs at once, five of them on the pool's
    ID unreserved, each alone in its own /dev/shm. Discovery as the middleware has it
    (SYSTEM_DEFAULT), under which a shared /dev/shm would carry the crosstalk.
    """
    env = shm_env(one_id)
    pool_id = int(env["ROS_ISOLATED_TEST_DOMAINS"])
    rendezvous = tmp_path / "rendezvous"
    rendezvous.mkdir()
    tokens = [f"p{index}_{uuid.uuid4().hex[:6]}" for index in range(6)]
    for token in tokens:
        args = ["run", "--isolation", "namespace", "--discovery-range", SHM_RANGE,
                "--junit-xml", str(tmp_path / f"{token}.xml"),
                "--", sys.executable, str(CROWD_PROBE), token, str(rendezvous), "6",
                "--listen", "3"]  # fmt: skip
        start_cli(args, env, tmp_path / f"{token}.log", started)
    reserved = []
    for process, token in zip(started, tokens, strict=True):
        code = process.wait(HUNG)
        output = (tmp_path / f"{token}.log").read_text()
        (report,) = reports(output)
        assert report["own"] > 0, f"DDS did not work in the namespace:\n{output}"
        assert report["met_all"], f"not all six were up at once:\n{output}"
        assert report["foreign"] == {}, f"crosstalk over shared memory:\n{output}"
        assert code == 0, output
        assert WAITING not in output, output
        assert domain_of(output) == pool_id, output
        properties = load_result(tmp_path / f"{token}.xml").properties
        assert properties["ros_domain_id"] == str(pool_id)
        reserved.append(properties["ros_domain_id_reserved"])
        if properties["ros_domain_id_reserved"] != "yes":
            assert NOT_RESERVED in output.splitlines()[0], output
    # One runner held the ID (unless another run on the machine took it meanwhile).
    assert reserved.count("yes") <= 1, reserved
    assert sum(value.startswith("no:") for value in reserved) >= 5, reserved


@pytest.mark.ros
@capabilities.RCLPY.mark
def test_control_two_shm_probes_sharing_a_domain_without_isolation_hear_each_other(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """Shared memory does cross: with isolation disabled, two probes on one ID hear each other.

    Same transports and discovery range as the probes above; without this the silence
    above could be a broken SHM transport.
    """
    domain = one_id["ROS_ISOLATED_TEST_DOMAINS"]
    env = {
        **shm_env(one_id),
        "DISABLE_ROS_ISOLATION": "1",
        "ROS_DOMAIN_ID": domain,
        "ROS_AUTOMATIC_DISCOVERY_RANGE": SHM_RANGE,
    }
    rendezvous = tmp_path / "rendezvous"
    rendezvous.mkdir()
    tokens = ["shared_a", "shared_b"]
    for token in tokens:
        args = ["run", "--", sys.executable, str(CROWD_PROBE), token, str(rendezvous), "2",
                "--listen", "3"]  # fmt: skip
        start_cli(args, env, tmp_path / f"{token}.log", started)
    for process, token in zip(started, tokens, strict=True):
        process.wait(HUNG)
        output = (tmp_path / f"{token}.log").read_text()
        (report,) = reports(output)
        other = tokens[1 - tokens.index(token)]
        assert report["foreign"].get(other, 0) > 0, f"no crosstalk without isolation:\n{output}"


# --- 3. two processes of one test, inside its namespace -----------------------------------


@pytest.mark.ros
@capabilities.RCLPY.mark
@pytest.mark.parametrize("transport", ["UDPv4", "SHM"])
def test_two_processes_of_one_test_talk_inside_its_namespace(
    env: dict[str, str], tmp_path: Path, transport: str
) -> None:
    """Over loopback (UDP, which needs lo up with multicast) and over its own /dev/shm."""
    rendezvous = tmp_path / "rendezvous"
    rendezvous.mkdir()
    probe = f"{sys.executable} {CROWD_PROBE}"
    net = tmp_path / "net"
    # Each probe's report into a file of its own: on one pipe their lines could interleave.
    script = (
        f"readlink /proc/self/ns/net > {net}; "
        f"{probe} inner_a {rendezvous} 2 --listen 2 > {tmp_path}/a.out & "
        f"{probe} inner_b {rendezvous} 2 --listen 2 > {tmp_path}/b.out; wait"
    )
    done = run_cli(
        ["run", "--isolation", "namespace", "--", "sh", "-c", script],
        {**env, "FASTDDS_BUILTIN_TRANSPORTS": transport},
    )
    assert NAMESPACES in done.stdout.splitlines()[0], done.stdout
    assert net.read_text().strip() != os.readlink("/proc/self/ns/net"), "not in its own network"
    outputs = "".join((tmp_path / name).read_text() for name in ("a.out", "b.out"))
    found = reports(outputs)
    assert len(found) == 2, done.stdout + done.stderr + outputs
    for report in found:
        assert report["own"] > 0 and report["met_all"], outputs
        heard = set(report["foreign"])
        assert heard and heard <= {"inner_a", "inner_b"}, f"they did not hear each other: {report}"


# --- 4. where namespaces are forbidden ----------------------------------------------------


def in_user_namespace(
    env: dict[str, str], args: Sequence[str], forbid: bool
) -> subprocess.CompletedProcess[str]:
    """``ros-isolated-test ARGS`` inside a user namespace of its own (the host untouched).

    With ``forbid``, ``user.max_user_namespaces`` is 0 there first: every user namespace
    the runner asks for fails with ENOSPC, as on a host where they are turned off.
    """
    return run_process([*user_namespace_prefix(forbid), CLI, *args], env)


@pytest.mark.parametrize("forbid", [True, False], ids=["forbidden", "control-allowed"])
def test_namespace_mode_refuses_where_user_namespaces_are_forbidden(
    env: dict[str, str], tmp_path: Path, forbid: bool
) -> None:
    """One line naming the cause and the fix, exit 2, nothing run, a result file.

    The control runs the same runner in the same kind of user namespace without the
    limit: there it runs the test in namespaces, so the refusal is the limit's doing.
    """
    result = tmp_path / "r.xml"
    marker = tmp_path / "ran"
    done = in_user_namespace(
        env,
        ["run", "--isolation", "namespace", "--junit-xml", str(result),
         "--", "touch", str(marker)],
        forbid,
    )  # fmt: skip
    if not forbid:
        assert done.returncode == 0, done.stdout + done.stderr
        assert NAMESPACES in done.stdout.splitlines()[0], done.stdout
        assert marker.exists()
        return
    line = the_error_line(done)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "user.max_user_namespaces is 0" in line, line
    assert "sysctl -w user.max_user_namespaces=" in line and "isolation auto" in line, line
    assert not marker.exists(), "the test ran although its namespaces were refused"
    summary = load_result(result)
    assert summary.only.outcome == "failure"
    assert summary.only.message == line.removeprefix(ERROR_PREFIX)
    assert summary.properties["exit"] == "not run"


@pytest.mark.parametrize("forbid", [True, False], ids=["forbidden", "control-allowed"])
def test_auto_falls_back_to_the_domain_id_where_user_namespaces_are_forbidden(
    env: dict[str, str], tmp_path: Path, forbid: bool
) -> None:
    """``auto`` runs the test on its reserved ID alone and says so, first in the header."""
    result = tmp_path / "r.xml"
    done = in_user_namespace(
        env,
        ["run", "--isolation", "auto", "--junit-xml", str(result), "--",
         sys.executable, "-c", "print('the test ran')"],
        forbid,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "the test ran" in done.stdout
    header = done.stdout.splitlines()[0]
    properties = load_result(result).properties
    if not forbid:
        assert NAMESPACES in header, done.stdout
        assert properties["isolation"] == "namespace (auto)"
        return
    assert "isolation auto: by the domain ID alone, no namespaces" in header, header
    assert "as namespaces are not allowed here: user namespaces are turned off" in done.stdout
    assert "user.max_user_namespaces is 0" in done.stdout, done.stdout
    assert properties["isolation"].startswith("domain (auto: "), properties
    assert "user.max_user_namespaces is 0" in properties["isolation"]


@capabilities.SECCOMP.mark
@pytest.mark.parametrize(
    ("isolation", "denied"),
    [("namespace", "unshare"), ("auto", "unshare"), ("namespace", "acct")],
    ids=["namespace-refused", "auto-falls-back", "control-unrelated-syscall-denied"],
)
def test_a_seccomp_filter_forbidding_unshare_is_named(
    env: dict[str, str], tmp_path: Path, isolation: str, denied: str
) -> None:
    """Docker's default profile fails unshare(2) with EPERM: the refusal names the filter.

    The control denies another system call under the same filter: namespaces then work,
    so the refusal is the unshare rule's doing.
    """
    result = tmp_path / "r.xml"
    runner = ["run", "--isolation", isolation, "--junit-xml", str(result), "--", "true"]
    done = run_process([*seccomp_prefix(denied), CLI, *runner], env)
    if denied != "unshare":
        assert done.returncode == 0, done.stdout + done.stderr
        assert NAMESPACES in done.stdout.splitlines()[0], done.stdout
        return
    named = "a seccomp filter forbids unshare(2) here, as Docker's default profile does"
    if isolation == "auto":
        assert done.returncode == 0, done.stdout + done.stderr
        assert "isolation auto: by the domain ID alone" in done.stdout.splitlines()[0]
        assert named in load_result(result).properties["isolation"]
        return
    line = the_error_line(done)
    assert done.returncode == 2, done.stdout + done.stderr
    assert named in line and "--security-opt seccomp=unconfined" in line, line
    assert load_result(result).only.message == line.removeprefix(ERROR_PREFIX)


# --- 5. a daemon left behind ---------------------------------------------------------------


@pytest.mark.ros
@capabilities.RCLPY.mark
def test_daemon_left_behind_in_namespaces_leaves_nothing_alive(
    env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    """Through the RUNNER, namespace mode asked for in the test's ENV (CMake's way).

    The double-forked rclpy talker, in the test's network namespace (read while it
    talks, after the test's main process left it behind), is in the runner's tree all
    the same (one PID namespace, the runner its subreaper): named as stopped, and gone
    when the runner returns.
    """
    tag = uuid.uuid4().hex
    pid_file, net_file = tmp_path / "talker.pid", tmp_path / "talker.net"
    talker = f"{sys.executable} {DAEMON_TALKER} {pid_file} ns-daemon"
    script = f'{talker} && readlink "/proc/$(cat {pid_file})/ns/net" > {net_file}'
    args = ament_args(
        tmp_path / "talker.xml",
        ["sh", "-c", script],
        "--generate-result-on-success",
        "--env",
        f"{ISOLATION}=namespace",
        f"{TAG_VAR}={tag}",
    )
    done = run_runner(runner_script, args, env, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert NAMESPACES in done.stdout.splitlines()[0], done.stdout
    assert net_file.read_text().strip() != os.readlink("/proc/self/ns/net"), "not in its own"
    daemon = int(pid_file.read_text())
    assert re.search(rf"stopped process {daemon}\b", done.stdout), done.stdout
    assert carrying(f"{TAG_VAR}={tag}") == [], "a process of the test outlived its runner"
    assert load_result(tmp_path / "talker.xml").properties["isolation"] == "namespace"


# --- what else the runner promises still holds ------------------------------------------


#: A test that says it is ready, then waits for SIGTERM and says it came (exit 7). Python
#: (unlike a shell) leaves the signal mask it was started with as it is.
TRAP = r"""
import pathlib, signal, sys, time
folder = pathlib.Path(sys.argv[1])
def stop(signum, frame):
    (folder / "received").write_text(signal.Signals(signum).name)
    sys.exit(7)
signal.signal(signal.SIGTERM, stop)
(folder / "ready").touch()
while True:
    time.sleep(0.1)
"""


def test_signal_to_the_runner_reaches_the_test_in_its_namespaces(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    runner = start_cli(
        ["run", "--isolation", "namespace", "--junit-xml", str(tmp_path / "r.xml"),
         "--", sys.executable, "-c", TRAP, str(tmp_path)],
        env,
        tmp_path / "runner.log",
        started,
    )  # fmt: skip
    wait_for(tmp_path / "ready")
    runner.send_signal(signal.SIGTERM)
    code = runner.wait(HUNG)
    log = (tmp_path / "runner.log").read_text()
    assert (tmp_path / "received").read_text() == "SIGTERM", log
    assert code == 128 + signal.SIGTERM, log
    exit_property = load_result(tmp_path / "r.xml").properties["exit"]
    assert "SIGTERM" in exit_property and "exited with code 7" in exit_property, exit_property


def test_the_runner_script_reads_the_isolation_from_its_environment(
    env: dict[str, str], runner_script: str, tmp_path: Path, shm_name: str
) -> None:
    """Exported where colcon or ctest runs, it reaches every test of the package."""
    result = tmp_path / "t.xml"
    command = [sys.executable, "-c", LOOK, shm_name]
    args = ament_args(result, command, "--generate-result-on-success")
    done = run_runner(runner_script, args, {**env, ISOLATION: "namespace"}, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert NAMESPACES in done.stdout.splitlines()[0], done.stdout
    assert seen(done.stdout)["net"] != os.readlink("/proc/self/ns/net"), done.stdout
    assert load_result(result).properties["isolation"] == "namespace"


# --- contradictions and bad values ------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "extra", "said"),
    [
        (["--discovery-range", "SUBNET"], {}, "discovery range is SUBNET"),
        ([], {"ROS_STATIC_PEERS": "127.0.0.1;10.20.30.40"}, "names another host (10.20.30.40)"),
    ],
    ids=["subnet", "remote-static-peer"],
)
def test_namespace_mode_refuses_discovery_that_needs_the_outside_network(
    env: dict[str, str], tmp_path: Path, options: list[str], extra: dict[str, str], said: str
) -> None:
    result = tmp_path / "r.xml"
    done = run_cli(
        ["run", "--isolation", "namespace", *options, "--junit-xml", str(result), "--", "true"],
        {**env, **extra},
    )
    line = the_error_line(done)
    assert done.returncode == 2, done.stdout + done.stderr
    assert said in line and "loopback only" in line, line
    assert load_result(result).only.message == line.removeprefix(ERROR_PREFIX)


def test_control_loopback_static_peers_are_fine_in_namespaces(env: dict[str, str]) -> None:
    """Peers on loopback are inside the test's network: not refused, and not warned about."""
    done = run_cli(
        ["run", "--isolation", "namespace", "--", "true"],
        {**env, "ROS_STATIC_PEERS": "localhost;127.0.0.1;::1"},
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "WARNING: ROS_STATIC_PEERS" not in done.stdout, done.stdout


@pytest.mark.parametrize("how", ["option", "variable", "runner-env"])
def test_an_unknown_isolation_mode_is_a_usage_error(
    env: dict[str, str], runner_script: str, tmp_path: Path, how: str
) -> None:
    result = tmp_path / "r.xml"
    if how == "option":
        done = run_cli(
            ["run", "--isolation", "sandbox", "--junit-xml", str(result), "--", "true"], env
        )
    elif how == "variable":
        done = run_cli(
            ["run", "--junit-xml", str(result), "--", "true"], {**env, ISOLATION: "sandbox"}
        )
    else:
        args = ament_args(result, ["true"], "--env", f"{ISOLATION}=sandbox")
        done = run_runner(runner_script, args, env, cwd=tmp_path)
    line = the_error_line(done)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "'sandbox' is not an isolation mode" in line and "namespace" in line, line
    assert result.is_file()


def test_disabled_isolation_says_the_namespaces_are_not_applied(
    env: dict[str, str], shm_name: str
) -> None:
    done = run_cli(
        ["run", "--isolation", "namespace", "--", sys.executable, "-c", LOOK, shm_name],
        {**env, "DISABLE_ROS_ISOLATION": "1"},
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "WARNING: --isolation namespace is not applied" in done.stdout, done.stdout
    assert seen(done.stdout)["net"] == os.readlink("/proc/self/ns/net")


# --- the pytest plugin ---------------------------------------------------------------------

PLUGIN_TEST = """
import os

def test_look():
    interfaces = [line.split(":")[0].strip() for line in open("/proc/net/dev").readlines()[2:]]
    assert interfaces == ["lo"], interfaces
    assert os.readlink("/proc/self/ns/net") != os.environ["HOST_NET"]
"""


def pytest_session(
    env: dict[str, str], tmp_path: Path, isolation: str, *options: str
) -> subprocess.CompletedProcess[str]:
    (tmp_path / "test_look.py").write_text(PLUGIN_TEST)
    return run_process(
        [sys.executable, "-m", "pytest", "--ros-isolation", "-p", "no:cacheprovider",
         "-v", *options, "test_look.py"],
        {**env, ISOLATION: isolation, "HOST_NET": os.readlink("/proc/self/ns/net")},
        cwd=tmp_path,
    )  # fmt: skip


def test_pytest_session_runs_in_namespaces_of_its_own(env: dict[str, str], tmp_path: Path) -> None:
    done = pytest_session(env, tmp_path, "namespace")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "isolation namespace: network (loopback only)" in done.stdout, done.stdout


def test_control_pytest_session_in_domain_mode_shares_the_hosts_network(
    env: dict[str, str], tmp_path: Path
) -> None:
    done = pytest_session(env, tmp_path, "domain")
    assert done.returncode == 1, done.stdout + done.stderr
    assert "AssertionError" in done.stdout and "isolation namespace" not in done.stdout


@pytest.mark.parametrize(("isolation", "code"), [("namespace", 4), ("auto", 1)])
def test_pytest_xdist_workers_cannot_enter_namespaces(
    env: dict[str, str], tmp_path: Path, isolation: str, code: int
) -> None:
    """Their threads forbid it: ``namespace`` is a usage error, ``auto`` says it fell back."""
    done = pytest_session(env, tmp_path, isolation, "-n", "1")
    assert done.returncode == code, done.stdout + done.stderr
    if isolation == "namespace":
        assert "a process with threads cannot enter a user namespace" in done.stderr, done.stderr
    else:
        header = (
            "by the domain ID alone, as namespaces are not allowed here: pytest-xdist's workers"
        )
        assert header in done.stdout, done.stdout


def test_a_namespace_run_holds_a_free_id_and_says_so(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """With an ID free it is reserved as in domain mode (``status`` shows it meanwhile)."""
    ready = tmp_path / "ready"
    go = tmp_path / "go"
    script = f"import pathlib, time\npathlib.Path({str(ready)!r}).touch()\n" + (
        f"while not pathlib.Path({str(go)!r}).exists(): time.sleep(0.02)"
    )
    log = tmp_path / "runner.log"
    runner = start_cli(
        ["run", "--isolation", "namespace", "--", sys.executable, "-c", script], env, log, started
    )
    try:
        wait_for(ready)
        status = run_cli(["status", "--json"], env)
    finally:
        go.touch()
    rows = [row for row in json.loads(status.stdout) if row.get("pid") == runner.pid]
    assert runner.wait(HUNG) == 0, log.read_text()
    output = log.read_text()
    assert NAMESPACES in output.splitlines()[0] and NOT_RESERVED not in output, output
    assert [row["domain_id"] for row in rows] == [domain_of(output)], status.stdout


def test_status_ignores_the_isolation_mode(env: dict[str, str]) -> None:
    """Only runs read it: a bad value exported for them never breaks ``status``."""
    done = run_cli(["status"], {**env, ISOLATION: "sandbox"})
    assert done.returncode == 0, done.stdout + done.stderr
    control = run_cli(["run", "--", "true"], {**env, ISOLATION: "sandbox"})
    assert control.returncode == 2, control.stdout + control.stderr
