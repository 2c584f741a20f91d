"""Upstream's coordinators: which tool set a process's ROS_DOMAIN_ID, read from /proc.

Three tools of ROS users choose a domain ID, hold it by binding TCP port 32768+ID (as
ours does too: see ``port_guard``) and set ROS_DOMAIN_ID for what they start:

- colcon's domain-ID coordinator (colcon-ros-domain-id-coordinator): one ID per package's
  task, written into colcon's own environment, which every task's process inherits;
- upstream's ``run_test_isolated.py`` (ament_cmake_ros, Jazzy's ``domain_coordinator``);
- Kilted's ``rmw_test_fixture`` (``run_rmw_isolated``, launch_ros's EnableRmwIsolation).

Each sets the variable in its own process after it started, and /proc/<pid>/environ shows
the environment a process started with, never a later change. That is the evidence: going
up from a process, the first ancestor that did not start with the value is the one that
set it. It counts as a tool's only when that ancestor is one of these tools and the ID's
port is held now (their lock, held while what they started lives).

colcon sets values without the coordinator too (a package's environment hook,
``set;ROS_DOMAIN_ID;5``), and port 32768+ID lies in Linux's ephemeral range (anything may
hold it, our own runner holding that ID too). So colcon's counts only when colcon itself
holds the port: a socket bound to it among colcon's own descriptors, which only the
coordinator's extension, loaded in that colcon, makes (a Python module leaves no other
mark in /proc). Where the kernel cannot show who holds a port (sock_diag's bound-only
sockets: Linux 6.8 and later) or colcon's descriptors cannot be read, it is no tool's;
:func:`unseen_colcon` tells the first case apart, for the refusal to say why.

A user's ``export ROS_DOMAIN_ID=5`` is never taken for a tool's: the shell that ran it is
the first ancestor without the value, and a shell is no tool; ``ROS_DOMAIN_ID=5 colcon
test`` gives colcon itself the value, which the coordinator then replaces (the user's
value stays in :attr:`Setter.own_value`). A value set inside the process that asks (a
conftest, a pytest plugin) is not in its own /proc entry: nobody's but the user's. Where
/proc shows no ancestors (another OS, a PID namespace that hides them), nothing is found.
"""

from __future__ import annotations

import itertools
import os

from ros_isolated_test.domain_coordinator import port_guard
from ros_isolated_test.domain_coordinator.pool import HIGHEST_VALID_ID
from ros_isolated_test.domain_coordinator.squatters import domain_value
from ros_isolated_test.process import proc

_VARIABLE = b"ROS_DOMAIN_ID="
#: Kinds of setter, as ``status`` names them (its HELD BY column and ``via``).
COLCON = "colcon"
UPSTREAM = "upstream"
FIXTURE = "fixture"
#: What each kind is, for messages.
NAMES = {
    COLCON: "colcon's domain-ID coordinator (colcon-ros-domain-id-coordinator)",
    UPSTREAM: "upstream's run_test_isolated.py (ament_cmake_ros)",
    FIXTURE: "Kilted's rmw_test_fixture (run_rmw_isolated, EnableRmwIsolation)",
}
#: Short names, where the long one was said already.
SHORT = {
    COLCON: "colcon's domain-ID coordinator",
    UPSTREAM: "upstream's run_test_isolated.py",
    FIXTURE: "Kilted's rmw_test_fixture",
}
#: colcon's variable naming the extensions it must not load, and the coordinator's name there.
BLOCKLIST_VAR = b"COLCON_EXTENSION_BLOCKLIST="
_COORDINATOR_ENTRY = b"ros_domain_id"
#: Ancestors looked at, at most: a tree deeper than this is no tool's.
_DEPTH = 64


class Setter:
    """The tool that set a process's ROS_DOMAIN_ID, and holds the ID's port."""

    __slots__ = ("command", "domain_id", "kind", "own_value", "pid", "value")

    def __init__(
        self, kind: str, pid: int, command: str, value: str, domain_id: int, own_value: str | None
    ) -> None:
        #: :data:`COLCON`, :data:`UPSTREAM` or :data:`FIXTURE`.
        self.kind = kind
        self.pid = pid
        #: The tool's command line, as /proc shows it (not display-safe).
        self.command = command
        #: The value it set, and the domain ROS reads from it.
        self.value = value
        self.domain_id = domain_id
        #: ROS_DOMAIN_ID the tool itself started with (a user's export), None when unset.
        self.own_value = own_value

    @property
    def name(self) -> str:
        return NAMES[self.kind]

    @property
    def short(self) -> str:
        return SHORT[self.kind]

    def __repr__(self) -> str:
        return f"Setter({self.kind}, pid={self.pid}, value={self.value!r})"


def variable(block: bytes, name: bytes = _VARIABLE) -> str | None:
    """The value of ``name`` (``NAME=``) in an environment block; None when it is not set."""
    start = block.find(name)
    while start > 0 and block[start - 1] != 0:
        start = block.find(name, start + 1)
    if start < 0:
        return None
    end = block.find(b"\0", start)
    return block[start + len(name) : end if end >= 0 else None].decode("utf-8", "replace")


def _basename(arg: str) -> str:
    return arg.rsplit("/", 1)[-1]


def _is_colcon(argv: list[str]) -> bool:
    """Whether it is colcon: ``colcon ...`` (a script run by its interpreter), or ``-m``."""
    if any(_basename(arg) == "colcon" for arg in argv[:2]):
        return True
    return any(
        arg == "-m" and after.startswith("colcon_core") for arg, after in itertools.pairwise(argv)
    )


def _is_upstream_runner(argv: list[str]) -> bool:
    """ament_cmake_ros's run_test_isolated.py (ours has the same name, elsewhere)."""
    return any(
        _basename(arg) == "run_test_isolated.py" and "/ament_cmake_ros/" in arg for arg in argv[:3]
    )


def _runs_fixture(pid: int) -> bool:
    """Kilted's fixture is loaded in the process: run_rmw_isolated, or a launch with it."""
    return b"rmw_test_fixture_implementation" in proc.maps(pid)


def kind_of(pid: int, block: bytes) -> str | None:
    """Which tool ``pid`` is (``block``: its environment); None for anything else."""
    argv = proc.argv(pid)
    if _is_colcon(argv):
        blocked = variable(block, BLOCKLIST_VAR)
        if blocked is not None and _COORDINATOR_ENTRY.decode() in blocked:
            return None  # the coordinator is not loaded: something else set the ID
        return COLCON
    if _is_upstream_runner(argv):
        return UPSTREAM
    if _runs_fixture(pid):
        return FIXTURE
    return None


#: What keeps colcon's coordinator from setting IDs at all (colcon reads it).
BLOCK_COORDINATOR = (
    "COLCON_EXTENSION_BLOCKLIST=colcon_core.shell.ros_domain_id:"
    "colcon_core.event_handler.ros_domain_id"
)


def setter_of(pid: int, value: str | None = None, bound_shown: bool | None = None) -> Setter | None:
    """The tool that set ``pid``'s ROS_DOMAIN_ID (``value``; None: the one it started with).

    None when the value was set by anyone else (a shell, a script, the process itself),
    when the ID's port is not held, or when /proc cannot show the ancestors.
    ``bound_shown=False`` reads sockets as a kernel before Linux 6.8 shows them.
    """
    found = _first_without(pid, value)
    return None if found is None else _tool(*found, bound_shown)


def unseen_colcon(pid: int, value: str, bound_shown: bool | None = None) -> Setter | None:
    """colcon, which set ``value`` for ``pid``, where nobody can tell whether it holds the port.

    The ID's port is taken, by no listener (no coordinator listens), and the kernel shows
    no bound-only socket (``bound_shown``; None: ask ``port_guard``'s probe, which runs
    only here; False: as before Linux 6.8): the holder may be colcon's coordinator or any
    program, the ID the coordinator's or an environment hook's. None wherever
    :func:`setter_of` can answer.
    """
    found = _first_without(pid, value)
    if found is None:
        return None
    setter, block, _, own_value = found
    domain_id = domain_value(value)
    if domain_id is None or not 0 <= domain_id <= HIGHEST_VALID_ID:
        return None
    if kind_of(setter, block) != COLCON or not port_guard.port_is_taken(domain_id):
        return None
    if port_guard.listening_sockets(domain_id) or (
        port_guard.shows_bound_sockets() if bound_shown is None else bound_shown
    ):
        return None
    return Setter(COLCON, setter, proc.cmdline(setter), value, domain_id, own_value)


def unseen_cause(colcon: Setter) -> str:
    """Why :func:`unseen_colcon`'s ID is refused, and the fixes of colcon's side: one line."""
    return (
        f"ROS_DOMAIN_ID is already set to {colcon.value!r} by colcon (pid {colcon.pid}) and "
        f"port {port_guard.PORT_BASE + colcon.domain_id} is taken, but colcon's domain-ID "
        "coordinator cannot be told apart on this kernel (Linux before 6.8 shows no "
        "bound-only sockets): the port may be any program's and the ID a package's "
        "environment hook's; fix: run on Linux 6.8 or later, or block the coordinator "
        f"({BLOCK_COORDINATOR}) and the runner picks a free ID"
    )


def _first_without(pid: int, value: str | None) -> tuple[int, bytes, str, str | None] | None:
    """The first ancestor of ``pid`` that did not start with ``value``, and what it set.

    Its PID, environment block, the value and its own; None when ``pid`` did not start
    with the value, or /proc shows no such ancestor.
    """
    current = pid
    for depth in range(_DEPTH):
        block = proc.environ(current)
        started_with = variable(block)
        if depth == 0:
            if not block:
                return None  # gone, or not ours to read
            if value is None:
                value = started_with
            if value is None or started_with != value:
                return None  # set in this process after it started: not by its parent
        elif value is not None and started_with != value:
            return current, block, value, started_with
        stat = proc.read_stat(current)
        if stat is None or stat.ppid <= 0:
            return None  # the top of what this PID namespace shows
        current = stat.ppid
    return None


def _tool(
    pid: int, block: bytes, value: str, own_value: str | None, bound_shown: bool | None
) -> Setter | None:
    """``pid`` set ``value`` for its children: a :class:`Setter` if it is a tool holding it."""
    kind = kind_of(pid, block)
    domain_id = domain_value(value)
    if kind is None or domain_id is None or not 0 <= domain_id <= HIGHEST_VALID_ID:
        return None
    if kind == COLCON:
        if not holds_port(pid, domain_id, bound_shown):
            return None  # a hook's or anyone's value: the coordinator holds what it sets
    elif not port_guard.port_is_taken(domain_id):
        return None
    return Setter(kind, pid, proc.cmdline(pid), value, domain_id, own_value)


def holds_port(pid: int, domain_id: int, bound_shown: bool | None = None) -> bool:
    """Whether process ``pid`` itself holds the ID's port (not a child, not another process).

    One of its descriptors is a socket the kernel shows bound to 32768+ID (listening only,
    for ``bound_shown=False``: what a kernel before Linux 6.8 shows).
    """
    if bound_shown is False:
        holding = port_guard.listening_sockets(domain_id)
    else:
        holding = port_guard.holding_sockets(domain_id)
    if not holding:
        return False
    wanted = {f"socket:[{inode}]" for inode in holding}
    folder = f"/proc/{pid}/fd"
    try:
        descriptors = os.listdir(folder)
    except OSError:
        return False  # gone, or not ours to read
    for descriptor in descriptors:
        try:
            if os.readlink(f"{folder}/{descriptor}") in wanted:
                return True
        except OSError:
            continue  # closed meanwhile
    return False
