"""``port_guard``: the TCP port 32768+ID by which upstream's ``domain_coordinator`` claims an ID.

Claiming binds the port as upstream does (no SO_REUSEADDR): while it is bound nobody
else can bind it, and a port another socket holds, even bound and idle, cannot be
claimed; both have their control, the same port once let go. The socket is not
inherited by the test the runner starts, so a holder's ID comes free when it lets go
whatever its test still runs.

Living beside upstream's coordinator, both ways, with real upstream processes: our runner
steps over the ID upstream holds (and ``status`` names its port), and upstream steps
over the ID our coordinator or a running runner holds. An unrelated program on the port
(IPv4 or IPv6, any address) is stepped over the same way.

Ports 32768+ID are machine-wide, so tests pick IDs whose port is free right now, from
215-232 where they can: outside the default pool and upstream's 1-100, so that other
runs on this machine rarely contend with them.
"""

from __future__ import annotations

import errno
import json
import os
import socket
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, run_cli
from helpers.coordinator import BIND_SCRIPT, UPSTREAM_SCRIPT
from helpers.domains import free_ids
from helpers.processes import DEADLINE, WAIT_SCRIPT, Children, wait_for

from ros_isolated_test.domain_coordinator import (
    POOL_ENV,
    DomainCoordinator,
    DomainUse,
    domain_uses,
)
from ros_isolated_test.domain_coordinator.port_guard import (
    PORT_BASE,
    claim_port,
    holding_sockets,
    listening_sockets,
    port_is_taken,
    shows_bound_sockets,
)

#: Says it runs (its exec done: descriptors closed on exec are closed by then), then keeps
#: running until its stdin closes, with every descriptor it was given.
IDLE_CHILD = "import sys; print('running', flush=True); sys.stdin.read()"


def _bind(port: int) -> socket.socket:
    """A plain socket bound to ``port`` on all interfaces, never listening."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.bind(("", port))
    except OSError:
        sock.close()
        raise
    return sock


def test_a_claimed_port_is_bound_and_nobody_else_can_bind_it() -> None:
    (domain_id,) = free_ids(1)
    assert not port_is_taken(domain_id)
    sock = claim_port(domain_id)
    assert sock is not None
    try:
        assert sock.getsockname()[1] == PORT_BASE + domain_id
        with pytest.raises(OSError) as raised:
            _bind(PORT_BASE + domain_id)
        assert raised.value.errno == errno.EADDRINUSE
        assert port_is_taken(domain_id)
        assert claim_port(domain_id) is None
    finally:
        sock.close()
    # The control: let go, the port is free for anyone (and for us again).
    assert not port_is_taken(domain_id)
    _bind(PORT_BASE + domain_id).close()


def test_a_port_another_socket_holds_bound_and_idle_cannot_be_claimed() -> None:
    """No SO_REUSEADDR on either side: a socket bound but not listening blocks the claim."""
    (domain_id,) = free_ids(1)
    other = _bind(PORT_BASE + domain_id)
    try:
        assert port_is_taken(domain_id)
        assert claim_port(domain_id) is None
    finally:
        other.close()
    sock = claim_port(domain_id)  # the control: the same port, let go
    assert sock is not None
    sock.close()


@pytest.mark.parametrize("family", [socket.AF_INET, socket.AF_INET6], ids=["ipv4", "ipv6"])
@pytest.mark.parametrize(
    "listening",
    [pytest.param(False, marks=capabilities.SOCK_DIAG_BOUND.mark), True],
    ids=["bound", "listening"],
)
def test_the_sockets_holding_a_port_are_named_bound_or_listening(
    family: socket.AddressFamily, listening: bool
) -> None:
    """The socket's own inode, as /proc/<pid>/fd shows it, whether it listens or, as the
    coordinators' do, is only bound (in no /proc/net/tcp table). The control: the same
    port let go holds nothing; another ID's port is not named."""
    domain_id, other_id = free_ids(2)
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.bind(("::" if family == socket.AF_INET6 else "", PORT_BASE + domain_id))
        if listening:
            sock.listen()
        inode = int(os.readlink(f"/proc/self/fd/{sock.fileno()}")[len("socket:[") : -1])
        assert holding_sockets(domain_id) == frozenset({inode})
        assert holding_sockets(other_id) == frozenset()
    finally:
        sock.close()
    assert holding_sockets(domain_id) == frozenset()


def test_the_kernel_is_said_to_show_bound_sockets_as_it_does_and_listeners_always() -> None:
    """The product's probe agrees with the capability's own (True on Linux 6.8+, False
    before): a bound socket is among the port's holders exactly then. The control: every
    kernel shows the same socket once it listens, and never among listeners before."""
    shown = capabilities.SOCK_DIAG_BOUND.missing is None
    assert shows_bound_sockets() is shown
    assert shows_bound_sockets() is shown  # asked again (its cached answer): the same
    (domain_id,) = free_ids(1)
    sock = _bind(PORT_BASE + domain_id)
    try:
        inode = os.fstat(sock.fileno()).st_ino
        assert (inode in (holding_sockets(domain_id) or ())) is shown
        assert listening_sockets(domain_id) == frozenset()
        sock.listen()
        assert listening_sockets(domain_id) == frozenset({inode})
        assert holding_sockets(domain_id) == frozenset({inode})
    finally:
        sock.close()


def test_a_child_started_while_the_port_is_claimed_does_not_keep_it(
    children: Children,
) -> None:
    """The runner's test must not hold its ID's port once the runner lets go.

    The control: an inheritable socket on the same port, passed to the same kind of
    child, does keep the port taken after the parent closed it.
    """
    (domain_id,) = free_ids(1)
    sock = claim_port(domain_id)
    assert sock is not None
    child = children.start([sys.executable, "-c", IDLE_CHILD], close_fds=False)
    assert children.first_line(child) == "running"
    sock.close()
    assert not port_is_taken(domain_id)
    children.finish(child)

    inherited = _bind(PORT_BASE + domain_id)
    inherited.set_inheritable(True)
    keeper = children.start([sys.executable, "-c", IDLE_CHILD], close_fds=False)
    assert children.first_line(keeper) == "running"
    inherited.close()
    assert port_is_taken(domain_id)
    children.finish(keeper)
    assert not port_is_taken(domain_id)


# -- living beside upstream's port-based domain_coordinator --------------------------------


def test_an_id_held_by_upstream_is_skipped(
    lock_dir: Path, env: dict[str, str], children: Children
) -> None:
    # An ID of upstream's range 1-100 that no squatter has either (upstream does not look
    # for them): the control at the end needs it free once upstream lets go.
    (chosen,) = free_ids(1, range(1, 101))
    upstream = children.python(UPSTREAM_SCRIPT, chosen)
    upstream_id = int(children.first_line(upstream))
    assert upstream_id == chosen
    (other,) = free_ids(1)

    assert DomainCoordinator(lock_dir, (upstream_id,)).try_reserve(["a"]) is None
    with DomainCoordinator(lock_dir, (upstream_id, other)).reserve(["a"]) as reservation:
        assert reservation.domain_id == other
    # Our default pool starts at 1, as upstream does: the runner must step over its ID.
    with DomainCoordinator(lock_dir, range(1, 102)).reserve(["a"]) as reservation:
        assert reservation.domain_id != upstream_id

    # Status lists every ID of the lock dir's files too: others' IDs are in use as well.
    ours = [item for item in domain_uses(lock_dir, (upstream_id,)) if item.domain_id == upstream_id]
    assert ours == [DomainUse(upstream_id, "port", None)]
    env[POOL_ENV] = str(upstream_id)
    result = run_cli(["status", "--json"], env)
    assert result.returncode == 0, result.stderr
    rows = [row for row in json.loads(result.stdout) if row["domain_id"] == upstream_id]
    assert rows == [{"domain_id": upstream_id, "via": "port"}]
    table = run_cli(["status"], env)
    assert table.returncode == 0, table.stderr
    assert "port 32768+ID taken" in table.stdout
    assert run_cli(["run", "--wait-timeout", "0", "--", "true"], env).returncode == 3

    assert children.finish(upstream) == 0
    with DomainCoordinator(lock_dir, (upstream_id,)).reserve(["a"]) as reservation:
        assert reservation.domain_id == upstream_id


def test_upstream_skips_an_id_our_coordinator_holds(lock_dir: Path, children: Children) -> None:
    ours, after = free_ids(2)
    with DomainCoordinator(lock_dir, (ours,)).reserve(["a"]) as reservation:
        assert reservation.domain_id == ours
        upstream = children.python(UPSTREAM_SCRIPT, ours, after)
        assert int(children.first_line(upstream)) == after
        assert children.finish(upstream) == 0
    # Control: with our ID released, the same selector gives upstream its first choice.
    upstream = children.python(UPSTREAM_SCRIPT, ours, after)
    assert int(children.first_line(upstream)) == ours
    assert children.finish(upstream) == 0


def test_upstream_skips_the_id_of_a_running_runner(
    env: dict[str, str], tmp_path: Path, children: Children
) -> None:
    ours, after = free_ids(2)
    env[POOL_ENV] = str(ours)
    pid_file, go = tmp_path / "test.pid", tmp_path / "go"
    runner = children.start(
        [CLI, "run", "--", sys.executable, "-c", WAIT_SCRIPT, str(pid_file), str(go)], env=env
    )
    try:
        wait_for(pid_file)
        upstream = children.python(UPSTREAM_SCRIPT, ours, after)
        assert int(children.first_line(upstream)) == after
        assert children.finish(upstream) == 0
    finally:
        go.touch()
    stdout, stderr = runner.communicate(timeout=DEADLINE)
    assert runner.returncode == 0, stdout + stderr
    assert f"Running with ROS_DOMAIN_ID {ours}" in stdout


@pytest.mark.parametrize("address", ["0.0.0.0", "127.0.0.1", "::"])
def test_an_unrelated_program_on_the_port_is_skipped(
    address: str, lock_dir: Path, children: Children
) -> None:
    if ":" in address:
        capabilities.require(capabilities.IPV6)
    taken, other = free_ids(2)
    binder = children.python(BIND_SCRIPT, address, PORT_BASE + taken)
    assert children.first_line(binder) == "bound"
    assert port_is_taken(taken)
    coordinator = DomainCoordinator(lock_dir, (taken, other))
    with coordinator.reserve(["a"]) as reservation:
        assert reservation.domain_id == other
    assert DomainCoordinator(lock_dir, (taken,)).try_reserve(["a"]) is None
    # Skipping an ID releases its lock again: it is not held by us, only its port is taken.
    assert domain_uses(lock_dir, (taken,)) == [DomainUse(taken, "port", None)]
    assert children.finish(binder) == 0
    with DomainCoordinator(lock_dir, (taken,)).reserve(["a"]) as reservation:
        assert reservation.domain_id == taken
