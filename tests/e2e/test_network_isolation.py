"""Two "hosts" on one domain ID: the runner's default discovery range keeps them apart.

Each host is a network namespace (linked to the other by a veth pair, so DDS sees two
machines on one subnet) and a PID namespace with its own /proc. The PID namespace is
needed because the coordinator refuses an ID while any process it can see in /proc
carries it: right on one machine, but two hosts do not see each other's processes.
Each host runs its test through its own runner with its own lock directory and a pool
of one ID, so both get domain 7. Host A runs a talker, host B a listener that must hear
its own token first (LOCALHOST still works inside a host) and then fails on A's token.

The addresses below exist only inside the two namespaces, which are always deleted.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities
from helpers.commands import CLI
from helpers.results import ResultSummary, load_result

pytestmark = [pytest.mark.ros, capabilities.RCLPY.mark]

HELPERS = Path(__file__).resolve().parents[1] / "helpers"
TALKER = HELPERS / "host_talker.py"
LISTENER = HELPERS / "token_listener.py"
#: A private range, assigned only inside the two namespaces.
ADDRESS_A = "10.203.77.1"
ADDRESS_B = "10.203.77.2"
PREFIX_LEN = 24
DOMAIN = "7"
#: After hearing itself: longer than the ~3 s a late joiner may wait for an announcement.
LISTEN_S = 5.0
READY_DEADLINE_S = 40.0
DISCOVERY_VARS = (
    "ROS_AUTOMATIC_DISCOVERY_RANGE",
    "ROS_LOCALHOST_ONLY",
    "ROS_STATIC_PEERS",
    "ROS_ISOLATED_TEST_DISCOVERY_RANGE",
    "ROS_DISTRO",
)


@dataclass(frozen=True)
class Host:
    namespace: str
    address: str


@dataclass(frozen=True)
class Hosts:
    a: Host
    b: Host


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30, check=False)
    if check and proc.returncode != 0:
        raise RuntimeError(f"`ip {' '.join(args)}` failed: {proc.stderr.strip()}")
    return proc


def _remove_namespace(name: str) -> None:
    """Stop what our tests left in it (normally nothing), then delete it."""
    pids = _ip("netns", "pids", name, check=False).stdout.split()
    for pid in pids:
        with contextlib.suppress(ProcessLookupError, ValueError):
            os.kill(int(pid), signal.SIGKILL)
    _ip("netns", "delete", name, check=False)


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    capabilities.require(capabilities.NETWORK_NAMESPACES, capabilities.UNSHARE)
    tag = f"rit-{os.getpid()}-{secrets.token_hex(2)}"
    a, b = Host(f"{tag}-a", ADDRESS_A), Host(f"{tag}-b", ADDRESS_B)
    created: list[str] = []
    try:
        for host in (a, b):
            _ip("netns", "add", host.namespace)
            created.append(host.namespace)
        # Made inside A with its peer put straight into B: the link never exists on the
        # machine's own network.
        _ip("-n", a.namespace, "link", "add", "rit0", "type", "veth", "peer", "name", "rit1",
            "netns", b.namespace)  # fmt: skip
        for host, device in ((a, "rit0"), (b, "rit1")):
            _ip("-n", host.namespace, "addr", "add", f"{host.address}/{PREFIX_LEN}", "dev", device)
            _ip("-n", host.namespace, "link", "set", device, "up")
            _ip("-n", host.namespace, "link", "set", "lo", "up")
        yield Hosts(a, b)
    finally:
        for name in created:
            _remove_namespace(name)


_UNSHARE = ("unshare", "--pid", "--fork", "--mount-proc", "--kill-child")


@dataclass(frozen=True)
class Side:
    """What one host's runner did: exit code, console, result file, the test's own report."""

    returncode: int
    output: str
    result: ResultSummary
    report: dict[str, Any]


def _host_env(base: Mapping[str, str], lock_dir: Path, extra: Mapping[str, str]) -> dict[str, str]:
    env = {key: value for key, value in base.items() if key not in DISCOVERY_VARS}
    lock_dir.mkdir(parents=True, exist_ok=True)
    env.update(ROS_ISOLATED_TEST_LOCK_DIR=str(lock_dir), ROS_ISOLATED_TEST_DOMAINS=DOMAIN)
    env.update(extra)
    return env


def _command(host: Host, junit: Path, options: Sequence[str], test: Sequence[str]) -> list[str]:
    runner = [CLI, "run", "--junit-xml", str(junit), *options, "--", sys.executable, *test]
    return ["ip", "netns", "exec", host.namespace, *_UNSHARE, *runner]


def _side(returncode: int, output: str, junit: Path) -> Side:
    reports = [line for line in output.splitlines() if line.startswith("RESULT ")]
    assert len(reports) == 1, f"expected one RESULT line from the test:\n{output}"
    return Side(returncode, output, load_result(junit), json.loads(reports[0][len("RESULT ") :]))


def exchange(
    hosts: Hosts,
    env: Mapping[str, str],
    tmp_path: Path,
    options_a: Sequence[str] = (),
    options_b: Sequence[str] = (),
    env_b: Mapping[str, str] | None = None,
) -> tuple[Side, Side]:
    """The talker on A until the listener on B is done; each through its own runner."""
    ready, stop = tmp_path / "talker-ready", tmp_path / "talker-stop"
    junit_a, junit_b = tmp_path / "a" / "talker.xml", tmp_path / "b" / "listener.xml"
    log_a = tmp_path / "a.log"
    talker = [str(TALKER), "alpha", str(ready), str(stop)]
    with log_a.open("w") as log:
        process_a = subprocess.Popen(
            _command(hosts.a, junit_a, options_a, talker),
            env=_host_env(env, tmp_path / "locks-a", {}),
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
        )
    try:
        # The talker first, and hearing itself: B then joins a host that is surely talking.
        deadline = time.monotonic() + READY_DEADLINE_S
        while not ready.exists():
            assert process_a.poll() is None, f"host A's test ended early:\n{log_a.read_text()}"
            assert time.monotonic() < deadline, f"host A never got going:\n{log_a.read_text()}"
            time.sleep(0.05)
        listener = [str(LISTENER), "bravo", "--listen", str(LISTEN_S)]
        proc_b = subprocess.run(
            _command(hosts.b, junit_b, options_b, listener),
            env=_host_env(env, tmp_path / "locks-b", env_b or {}),
            capture_output=True,
            text=True,
            timeout=90,
            check=False,
        )
        stop.touch()
        returncode_a = process_a.wait(timeout=30)
    finally:
        if process_a.poll() is None:
            process_a.kill()  # --kill-child takes the whole PID namespace with it
            process_a.wait(timeout=30)
    side_a = _side(returncode_a, log_a.read_text(), junit_a)
    side_b = _side(proc_b.returncode, proc_b.stdout + proc_b.stderr, junit_b)
    for side in (side_a, side_b):
        assert side.result.properties.get("ros_domain_id") == DOMAIN, side.output
        assert side.report["domain_id"] == DOMAIN, side.output
        assert side.report["own"] > 0, f"DDS did not work inside one host:\n{side.output}"
    return side_a, side_b


def _range_of(side: Side) -> str:
    return side.result.properties.get("ros_discovery_range", "")


def test_localhost_default_keeps_two_hosts_on_one_id_apart(
    hosts: Hosts, env: dict[str, str], tmp_path: Path
) -> None:
    a, b = exchange(hosts, env, tmp_path)
    assert (_range_of(a), _range_of(b)) == ("LOCALHOST", "LOCALHOST")
    assert b.report["foreign"] == {}, f"host B heard host A despite LOCALHOST:\n{b.output}"
    assert a.report["foreign"] == {}, f"host A heard host B despite LOCALHOST:\n{a.output}"
    assert (a.returncode, b.returncode) == (0, 0), a.output + b.output
    assert b.result.only.outcome == "passed", b.output


def test_subnet_control_shows_the_crosstalk(
    hosts: Hosts, env: dict[str, str], tmp_path: Path
) -> None:
    """Without this, silence above could be a broken veth rather than isolation."""
    subnet = ["--discovery-range", "SUBNET"]
    a, b = exchange(hosts, env, tmp_path, subnet, subnet)
    assert (_range_of(a), _range_of(b)) == ("SUBNET", "SUBNET")
    assert b.report["foreign"].get("alpha", 0) > 0, f"no crosstalk with SUBNET:\n{b.output}"
    assert b.returncode == 1, b.output
    assert b.result.only.outcome == "failure", b.output


def test_localhost_on_one_host_alone_is_enough(
    hosts: Hosts, env: dict[str, str], tmp_path: Path
) -> None:
    """A test run through the runner stays apart even from a host that discovers widely."""
    a, b = exchange(hosts, env, tmp_path, options_a=["--discovery-range", "SUBNET"])
    assert (_range_of(a), _range_of(b)) == ("SUBNET", "LOCALHOST")
    assert b.report["foreign"] == {}, b.output
    assert b.returncode == 0, b.output


def test_static_peers_reach_the_other_host_as_the_warning_says(
    hosts: Hosts, env: dict[str, str], tmp_path: Path
) -> None:
    a, b = exchange(hosts, env, tmp_path, env_b={"ROS_STATIC_PEERS": hosts.a.address})
    assert (_range_of(a), _range_of(b)) == ("LOCALHOST", "LOCALHOST")
    assert b.result.properties.get("ros_static_peers") == hosts.a.address
    warning = f"WARNING: ROS_STATIC_PEERS={hosts.a.address}"
    assert warning in b.output and "beyond this machine" in b.output, b.output
    assert b.report["foreign"].get("alpha", 0) > 0, (
        f"static peers did not reach host A, so the warning would be wrong:\n{b.output}"
    )
    assert b.returncode == 1, b.output
