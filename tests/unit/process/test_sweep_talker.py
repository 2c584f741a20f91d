"""A double-forked rclpy talker is gone before the next test gets its ID, as upstream's is not.

The issue's promise: a domain ID is never handed to a test while any process of an
earlier test that used it is alive. A talker that daemonizes (double fork, its own
session) and keeps publishing for a while after SIGTERM is the hard case: the sweep must
have ended it before the runner releases the ID, or the next test, queued for that
very ID, hears it. The control runs the same two tests under upstream's RUNNER, which
hands the ID on while the talker still talks: the crosstalk the sweep prevents.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import uuid
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities, commands
from helpers.commands import REPO, run_runner
from helpers.process_tree import (
    POOL_VAR,
    WAIT_VAR,
    alive,
    describe,
    environ_of,
    read_pid,
    wait_for_pid,
)
from helpers.results import domain_of, load_result

HELPERS = REPO / "tests" / "helpers"
DAEMON_TALKER = HELPERS / "daemon_talker.py"
TOKEN_LISTENER = HELPERS / "token_listener.py"
#: Upstream's RUNNER, from the ament_cmake_ros installed beside us.
UPSTREAM_RUNNER = capabilities.UPSTREAM_RUNNER_PATH
LEAKED_TOKEN = "leaked-talker"

needs_rclpy = capabilities.RCLPY.mark


def listener_report(stdout: str) -> dict[str, Any]:
    match = re.search(r"^RESULT (\{.*\})$", stdout, re.MULTILINE)
    assert match, f"the listener printed no RESULT line:\n{stdout}"
    report: dict[str, Any] = json.loads(match.group(1))
    return report


def ament_args(result: Path, command: Sequence[str]) -> list[str]:
    return commands.ament_args(result, command, "--generate-result-on-success")


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
