"""Holding domain IDs in other processes, and reading back what the runner says about them.

The domain coordinator's tests hold IDs the way the tool's users do: in a child process
(our coordinator, upstream's port-based one, an unrelated program on the port, a bare
flock), in a real runner, or in a process left behind on its ID. The helpers here start
those, wait for them, and read ``status --json``, the ``id=`` line a test command prints
and the runner's one-line errors, so every test reads them alike.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

from helpers.commands import run_cli, start_cli
from helpers.processes import DEADLINE, poll_until

#: Holds an ID with our coordinator until its stdin closes. argv: lock dir, pool IDs.
HOLD_SCRIPT = """
import os, sys
from pathlib import Path
from ros_isolated_test.domain_coordinator import DomainCoordinator
os.umask(0o077)
pool = [int(arg) for arg in sys.argv[2:]]
reservation = DomainCoordinator(Path(sys.argv[1]), pool).try_reserve(["hold", *sys.argv[2:]])
print(reservation.domain_id if reservation else "none", flush=True)
sys.stdin.read()
if reservation:
    reservation.release()
"""

#: Holds an ID with upstream's domain_coordinator until stdin closes. argv: selector IDs.
UPSTREAM_SCRIPT = """
import itertools, sys
import domain_coordinator
ids = [int(arg) for arg in sys.argv[1:]]
selector = itertools.cycle(ids).__next__ if ids else None
with domain_coordinator.domain_id(selector) as domain_id:
    print(domain_id, flush=True)
    sys.stdin.read()
"""

#: An unrelated program listening on a TCP port until stdin closes. argv: address, port.
BIND_SCRIPT = """
import socket, sys
family = socket.AF_INET6 if ":" in sys.argv[1] else socket.AF_INET
sock = socket.socket(family, socket.SOCK_STREAM)
sock.bind((sys.argv[1], int(sys.argv[2])))
sock.listen()
print("bound", flush=True)
sys.stdin.read()
"""

#: Holds an exclusive flock of argv[1] (created if missing) until stdin closes.
FLOCK_SCRIPT = """
import fcntl, os, sys
fd = os.open(sys.argv[1], os.O_RDONLY | os.O_CREAT, 0o666)
fcntl.flock(fd, fcntl.LOCK_EX)
print("locked", flush=True)
sys.stdin.read()
"""

#: A stand-in for colcon with its domain-ID coordinator, saved as a file named ``colcon``:
#: holds port 32768+argv[1] unless argv[2] is "free", sets ROS_DOMAIN_ID=argv[1] in its own
#: environment, as the coordinator does in colcon's, and runs argv[3:] (stdin passed on).
COLCON_SCRIPT = """
import os, subprocess, sys
from ros_isolated_test.domain_coordinator.port_guard import claim_port
port = claim_port(int(sys.argv[1])) if sys.argv[2] != "free" else None
assert sys.argv[2] == "free" or port is not None, "port taken"
os.environ["ROS_DOMAIN_ID"] = sys.argv[1]
sys.exit(subprocess.call(sys.argv[3:]))
"""
#: A test command that prints its PID and ROS_DOMAIN_ID, then waits for its stdin to close.
WAIT_SCRIPT = 'echo "pid=$$ id=$ROS_DOMAIN_ID"; read -r stop'


def stand_in_colcon(folder: Path) -> Path:
    """:data:`COLCON_SCRIPT` as ``folder/colcon``, run as ``python folder/colcon ID hold CMD``."""
    path = folder / "colcon"
    path.write_text(COLCON_SCRIPT)
    return path


#: A test command that prints the ID it was given.
PRINT_ID = 'echo "id=$ROS_DOMAIN_ID"'
#: The columns of ``status``'s table, as a user reads its header (unit and e2e tests alike).
STATUS_COLUMNS = ["ID", "HELD", "BY", "PID", "USER", "STARTED", "GZ_PARTITION", "COMMAND"]


def without_domain_id() -> dict[str, str]:
    """This process's environment without ROS_DOMAIN_ID."""
    return {key: value for key, value in os.environ.items() if key != "ROS_DOMAIN_ID"}


def status_rows(env: dict[str, str]) -> list[dict[str, object]]:
    """``ros-isolated-test status --json``, which must succeed, as its rows."""
    listed = run_cli(["status", "--json"], env)
    assert listed.returncode == 0, listed.stdout + listed.stderr
    rows: list[dict[str, object]] = json.loads(listed.stdout)
    return rows


def error_lines(stderr: str) -> list[str]:
    """The lines of ``stderr`` that say something (blank ones dropped)."""
    return [line for line in stderr.splitlines() if line.strip()]


def ids_seen(stdout: str) -> list[int]:
    """The IDs a :data:`PRINT_ID` test command printed, in order."""
    return [int(line[3:]) for line in stdout.splitlines() if line.startswith("id=")]


def hold_the_pool(env: dict[str, str], tmp_path: Path, into: list[subprocess.Popen[bytes]]) -> Path:
    """A real runner holding the pool's one ID until the returned file exists."""
    go, got = tmp_path / "go", tmp_path / "holding"
    script = f"touch {got}; while [ ! -e {go} ]; do sleep 0.05; done"
    holder = start_cli(["run", "--", "sh", "-c", script], env, tmp_path / "holder.log", into)
    poll_until(lambda: got.exists() or holder.poll() is not None, "the holder never ran")
    assert got.exists(), (tmp_path / "holder.log").read_text()
    return go


def wait_for_environment(pid: int, domain_id: int) -> None:
    """Until the exec'd process shows the variable (a fork shows its parent's first)."""
    wait_for_entry(pid, f"ROS_DOMAIN_ID={domain_id}")


def wait_for_entry(pid: int, entry: str) -> None:
    """Until the exec'd process shows ``entry`` (``NAME=value``) in its environment."""
    wanted = entry.encode()
    deadline = time.monotonic() + DEADLINE
    while wanted not in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0"):
        assert time.monotonic() < deadline, "the process never showed its environment"
        time.sleep(0.01)


def wait_gone(pid: int) -> None:
    """Until ``pid`` is gone (reaped by whoever its parent is now)."""
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            os.kill(pid, 0)
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (ProcessLookupError, FileNotFoundError):
            return
        if state in ("Z", "X"):
            return
        assert time.monotonic() < deadline, f"process {pid} did not end"
        time.sleep(0.02)
