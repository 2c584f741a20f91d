"""Which tool set a process's ROS_DOMAIN_ID: evidence from /proc, never a guess.

A process's ROS_DOMAIN_ID is a tool's when the first ancestor that did not start with it
is colcon (its domain-ID coordinator), upstream's run_test_isolated.py or Kilted's
rmw_test_fixture, and that ID's port is held (colcon's: by colcon itself). Real upstream
runner and fixture; colcon by a stand-in named as colcon is (the real one:
tests/e2e/test_colcon_coordinator.py). Every positive case has its negative beside it: a
shell's export with the port held by someone, a value set inside the process that asks,
colcon with the coordinator blocked, or not holding the port while another process does.
"""

from __future__ import annotations

import os
import socket
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import ament_args
from helpers.coordinator import WAIT_SCRIPT, stand_in_colcon, wait_for_environment
from helpers.distros import KILTED
from helpers.domains import free_ids
from helpers.processes import Children

from ros_isolated_test.domain_coordinator import port_guard, upstream


def _waiting_child(children: Children, argv: list[str], **popen: object) -> tuple[int, int]:
    """Start ``argv`` ending in :data:`WAIT_SCRIPT`; the waiting shell's PID and its ID."""
    process = children.start(argv, **popen)
    line = children.first_line(process)
    while not line.startswith("pid="):  # a runner's own lines come first
        line = children.first_line(process)
    pid, domain = (int(part.split("=", 1)[1]) for part in line.split())
    wait_for_environment(pid, domain)
    return pid, domain


def _clean_env(**extra: str) -> dict[str, str]:
    env = {key: value for key, value in os.environ.items() if key != "ROS_DOMAIN_ID"}
    env.pop(upstream.BLOCKLIST_VAR.decode().rstrip("="), None)
    return {**env, **extra}


def _colcon_child(
    children: Children, tmp_path: Path, domain_id: int, hold: str = "hold", **env: str
) -> tuple[int, int]:
    """A shell started by the colcon stand-in with ``domain_id``: its PID, and colcon's."""
    colcon = stand_in_colcon(tmp_path)
    argv = [sys.executable, str(colcon), str(domain_id), hold, "sh", "-c", WAIT_SCRIPT]
    pid, _ = _waiting_child(children, argv, env=_clean_env(**env))
    return pid, children.processes[-1].pid


@capabilities.SOCK_DIAG_BOUND
def test_an_id_colcons_coordinator_set_and_holds_is_colcons(
    children: Children, tmp_path: Path
) -> None:
    domain_id = free_ids(1)[0]
    pid, colcon = _colcon_child(children, tmp_path, domain_id)
    setter = upstream.setter_of(pid)
    assert setter is not None
    assert (setter.kind, setter.pid, setter.domain_id, setter.own_value) == (
        upstream.COLCON,
        colcon,
        domain_id,
        None,
    )
    assert setter.value == str(domain_id) and "colcon" in setter.command
    # This kernel shows colcon's socket (the probe asked): nothing unseen about it.
    assert upstream.unseen_colcon(pid, str(domain_id)) is None
    # Asked with another value than the process started with: not what colcon gave it.
    assert upstream.setter_of(pid, str(domain_id + 1)) is None


@capabilities.SOCK_DIAG_BOUND
def test_a_users_id_that_colcon_started_with_is_kept_as_the_users(
    children: Children, tmp_path: Path
) -> None:
    """``ROS_DOMAIN_ID=5 colcon test``: the coordinator gives the task another ID, and
    the user's stays known, so the runner can refuse it as the user's."""
    domain_id = free_ids(1)[0]
    pid, _ = _colcon_child(children, tmp_path, domain_id, ROS_DOMAIN_ID="5")
    setter = upstream.setter_of(pid)
    assert setter is not None and setter.own_value == "5"


def test_colcon_without_the_coordinator_holding_the_port_sets_nobodys_id(
    children: Children, tmp_path: Path
) -> None:
    domain_id = free_ids(1)[0]
    pid, _ = _colcon_child(children, tmp_path, domain_id, hold="free")
    assert upstream.setter_of(pid) is None


@capabilities.SOCK_DIAG_BOUND
@pytest.mark.parametrize("holder", ["bound", "listening"])
def test_colcon_not_holding_the_port_sets_nobodys_id_whoever_else_holds_it(
    children: Children, tmp_path: Path, holder: str
) -> None:
    """colcon set it (an environment hook's value) and another process holds 32768+ID (our
    runner's idle claim, a listener): not colcon's coordinator's, whose socket is colcon's
    own. The control: the same colcon holding it itself is the coordinator's."""
    domain_id = free_ids(1)[0]
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.bind(("", port_guard.PORT_BASE + domain_id))
        if holder == "listening":
            sock.listen()
        pid, _ = _colcon_child(children, tmp_path, domain_id, hold="free")
        assert port_guard.port_is_taken(domain_id)
        assert upstream.setter_of(pid) is None
        assert not upstream.holds_port(children.processes[-1].pid, domain_id)
        assert upstream.holds_port(os.getpid(), domain_id)
    finally:
        sock.close()
    pid, colcon = _colcon_child(children, tmp_path, domain_id)
    setter = upstream.setter_of(pid)
    assert setter is not None and (setter.kind, setter.pid) == (upstream.COLCON, colcon)


@pytest.mark.parametrize("holder", ["colcon", "listener", "nobody"])
def test_where_the_kernel_hides_bound_sockets_colcons_held_id_is_unseen(
    children: Children, tmp_path: Path, holder: str
) -> None:
    """The probe's answer given as on Linux before 6.8 (no bound-only socket shown): an ID
    colcon set whose port a socket holds unseen may be its coordinator's, said so in one
    line; one a listener holds (every kernel shows listeners) or nobody holds is not. The
    control, the probe asked on a kernel that shows them: the first test of this file."""
    domain_id = free_ids(1)[0]
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        if holder == "listener":
            listener.bind(("", port_guard.PORT_BASE + domain_id))
            listener.listen()
        hold = "hold" if holder == "colcon" else "free"
        pid, colcon = _colcon_child(children, tmp_path, domain_id, hold=hold)
        unseen = upstream.unseen_colcon(pid, str(domain_id), bound_shown=False)
    finally:
        listener.close()
    if holder != "colcon":
        assert unseen is None
        return
    assert unseen is not None
    assert (unseen.kind, unseen.pid, unseen.domain_id) == (upstream.COLCON, colcon, domain_id)
    assert upstream.setter_of(pid, bound_shown=False) is None  # what such a kernel shows
    line = upstream.unseen_cause(unseen)
    assert "\n" not in line
    assert line.startswith(
        f"ROS_DOMAIN_ID is already set to '{domain_id}' by colcon (pid {colcon}) and port "
        f"{port_guard.PORT_BASE + domain_id} is taken, but colcon's domain-ID coordinator "
        "cannot be told apart on this kernel (Linux before 6.8 shows no bound-only sockets): "
    )
    blocked = upstream.BLOCK_COORDINATOR
    assert f"; fix: run on Linux 6.8 or later, or block the coordinator ({blocked})" in line


def test_colcon_with_the_coordinator_blocked_sets_nobodys_id(
    children: Children, tmp_path: Path
) -> None:
    """COLCON_EXTENSION_BLOCKLIST naming it: whatever set the ID, it was no coordinator."""
    domain_id = free_ids(1)[0]
    blocked = "colcon_core.shell.ros_domain_id:colcon_core.event_handler.ros_domain_id"
    pid, _ = _colcon_child(children, tmp_path, domain_id, COLCON_EXTENSION_BLOCKLIST=blocked)
    assert upstream.setter_of(pid) is None


def test_a_shells_export_is_nobodys_tool_even_while_its_port_is_held(
    children: Children,
) -> None:
    """The parent that gave the value (this test, as a shell would) is no tool: a
    held port is no evidence by itself."""
    domain_id = free_ids(1)[0]
    port = port_guard.claim_port(domain_id)
    assert port is not None
    try:
        argv = ["sh", "-c", WAIT_SCRIPT]
        pid, _ = _waiting_child(children, argv, env=_clean_env(ROS_DOMAIN_ID=str(domain_id)))
        assert upstream.setter_of(pid) is None
    finally:
        port.close()


def test_a_value_set_inside_the_asking_process_is_not_a_tools() -> None:
    """This process did not start with it (a conftest, a plugin set it): nobody's tool."""
    started_with = upstream.variable(Path("/proc/self/environ").read_bytes())
    value = "9" if started_with != "9" else "10"
    assert upstream.setter_of(os.getpid(), value) is None
    assert upstream.setter_of(os.getpid()) is None or started_with is not None


@pytest.mark.ros
@capabilities.UPSTREAM_RUNNER
def test_an_id_upstreams_runner_set_is_upstreams(children: Children, tmp_path: Path) -> None:
    """Jazzy's run_test_isolated.py, real: it binds the port and sets the ID in itself."""
    runner = str(capabilities.UPSTREAM_RUNNER_PATH)
    argv = [
        sys.executable,
        "-u",
        runner,
        *ament_args(tmp_path / "r.xml", ["sh", "-c", WAIT_SCRIPT]),
    ]
    pid, domain_id = _waiting_child(children, argv, env=_clean_env())
    setter = upstream.setter_of(pid)
    assert setter is not None
    assert (setter.kind, setter.pid, setter.domain_id) == (
        upstream.UPSTREAM,
        children.processes[-1].pid,
        domain_id,
    )


@pytest.mark.ros
@capabilities.KILTED
def test_an_id_kilteds_fixture_set_is_the_fixtures(children: Children) -> None:
    """Kilted's run_rmw_isolated, real: the fixture's library is loaded in the setter."""
    fixture = KILTED.run_rmw_isolated
    assert fixture is not None
    env = KILTED.env(_clean_env())
    pid, domain_id = _waiting_child(children, [str(fixture), "sh", "-c", WAIT_SCRIPT], env=env)
    setter = upstream.setter_of(pid)
    assert setter is not None
    assert (setter.kind, setter.pid, setter.domain_id) == (
        upstream.FIXTURE,
        children.processes[-1].pid,
        domain_id,
    )
