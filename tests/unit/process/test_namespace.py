"""A test in namespaces of its own: a network, a /dev/shm and IPC of its own, as the same user.

``namespace.spawn`` starts the test in new user, network, mount and IPC namespaces:
loopback up (a socket connects to itself there), nothing else; a private tmpfs on
/dev/shm (a file written there never reaches the host's); the caller's own uid and gid
(a user maps only those, root every ID it has to itself, so other users' files stay
theirs). It is started as posix_spawn would start it: output on one descriptor,
default signal dispositions, candidates tried in turn, an exec error raised as that
OSError. ``try_in_child`` enters them for real in a child that exits; ``enter_here``
puts the calling process itself in them (the pytest plugin's way), refused while it
runs threads, and gives back the capabilities a user who is not root got there. Through
the runner too, with the control: in domain mode the test shares the host's network
and /dev/shm. ``describe_user`` names the supplementary groups a user cannot map. Why a
host refuses namespaces is ``test_namespace_diagnosis.py``; what crosses the boundary,
and the groups end to end, tests/e2e/test_namespace_boundary.py.
"""

from __future__ import annotations

import errno
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities
from helpers.commands import CLI, run_cli, run_process
from helpers.namespaces import LOOK, NAMESPACES, private_shm_name, seen, user_namespace_prefix
from helpers.process_tree import in_child
from helpers.processes import user_keywords
from helpers.results import load_result

from ros_isolated_test.process.namespace import NamespaceError

pytestmark = [capabilities.UNSHARE.mark]


@pytest.fixture
def shm_name() -> Iterator[str]:
    """A file name the test writes into its /dev/shm; removed from the host's if it got there."""
    with private_shm_name() as name:
        yield name


# --- namespace.spawn --------------------------------------------------------------------

#: The test ``spawn`` starts: a shell saying which signals it ignores, then Python saying
#: what it sees (argv: SHM_FILE) and a line on stderr.
INSIDE = r"""
import json, os, pathlib, socket, sys
pathlib.Path("/dev/shm", sys.argv[1]).write_text("inside")
server = socket.socket()
server.bind(("127.0.0.1", 0))
server.listen(1)
socket.create_connection(server.getsockname()).close()
interfaces = [line.split(":")[0].strip() for line in open("/proc/net/dev").readlines()[2:]]
kinds = ("net", "user", "mnt", "ipc", "pid")
print(json.dumps({
    "ns": {kind: os.readlink(f"/proc/self/ns/{kind}") for kind in kinds},
    "ids": [os.getuid(), os.getgid()], "interfaces": interfaces,
    "shm": sorted(os.listdir("/dev/shm")),
}), flush=True)
print("on stderr", file=sys.stderr, flush=True)
"""

#: ``namespace.spawn`` of :data:`INSIDE` (first candidate missing), SIGPIPE to its default.
#: argv: SHM_FILE. Prints what the test wrote, its exit code and what is outside.
SPAWN = """
import json, os, shutil, signal, sys
from ros_isolated_test.process import namespace
inside, name = sys.argv[1], sys.argv[2]
script = 'grep SigIgn /proc/self/status; exec "$0" -c "$1" "$2"'
argv = ["sh", "-c", script, sys.executable, inside, name]
read_end, write_end = os.pipe()
pid = namespace.spawn("sh", ["/nonexistent/sh", shutil.which("sh")], argv, dict(os.environ),
                      write_end, [signal.SIGPIPE])
os.close(write_end)
output = b""
while chunk := os.read(read_end, 65536):
    output += chunk
code = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
kinds = ("net", "user", "mnt", "ipc", "pid")
print(json.dumps({
    "output": output.decode(), "code": code,
    "ns": {kind: os.readlink(f"/proc/self/ns/{kind}") for kind in kinds},
    "ids": [os.getuid(), os.getgid()], "shm_outside": os.path.exists(f"/dev/shm/{name}"),
}))
"""


def _ignored(status_line: str) -> set[int]:
    mask = int(status_line.split()[1], 16)
    return {signum for signum in range(1, 65) if mask & (1 << (signum - 1))}


def test_spawn_starts_the_test_in_namespaces_of_its_own_as_the_same_user(shm_name: str) -> None:
    found: dict[str, Any] = in_child(SPAWN, INSIDE, shm_name)
    sig_ign, report, stderr_line = found["output"].splitlines()
    inside = json.loads(report)
    assert found["code"] == 0, found["output"]
    for kind in ("net", "user", "mnt", "ipc"):
        assert inside["ns"][kind] != found["ns"][kind], f"no {kind} namespace of its own"
    # The control: no PID namespace, so the runner still sees and ends every process.
    assert inside["ns"]["pid"] == found["ns"]["pid"]
    assert inside["interfaces"] == ["lo"], "loopback only (and up: it connected to itself)"
    assert inside["shm"] == [shm_name] and not found["shm_outside"], "a /dev/shm of its own"
    assert inside["ids"] == found["ids"], "the same uid and gid inside"
    assert stderr_line == "on stderr", "stderr goes where stdout goes"
    assert 13 not in _ignored(sig_ign), "SIGPIPE at its default, though Python ignores it"


#: ``namespace.spawn`` of commands that cannot start. Prints each error: type, errno, name.
CANNOT_START = """
import json, os
from ros_isolated_test.process import namespace
errors = []
for candidates in (["/nonexistent/rit"], ["/"]):
    read_end, write_end = os.pipe()
    try:
        namespace.spawn("rit-tool", candidates, ["rit-tool"], dict(os.environ), write_end, ())
    except OSError as error:
        errors.append([type(error).__name__, error.errno, error.filename])
    finally:
        os.close(read_end)
        os.close(write_end)
print(json.dumps(errors))
"""


def test_a_command_that_cannot_start_raises_as_posix_spawn_would() -> None:
    """The exec error inside, named as given: missing (127 to the runner), not runnable (126)."""
    missing, not_runnable = in_child(CANNOT_START)
    assert missing == ["FileNotFoundError", errno.ENOENT, "rit-tool"]
    assert not_runnable == ["PermissionError", errno.EACCES, "rit-tool"]


# --- try_in_child, threads, enter_here ------------------------------------------------

TRY = """
import json
from ros_isolated_test.process import namespace
found = namespace.try_in_child()
print(json.dumps(None if found is None else [found.step, found.errno, str(found)]))
"""


def test_try_in_child_enters_them_for_real_and_names_the_step_that_failed() -> None:
    assert in_child(TRY) is None, "namespaces work on this host"
    # Where user namespaces are turned off (a limit of 0, in a user namespace of its own):
    step, number, message = in_child(TRY, prefix=user_namespace_prefix(forbid=True))
    assert (step, number) == ("unshare", errno.ENOSPC)
    assert message == (
        "[Errno 28] cannot create user, network, mount and IPC namespaces (unshare): "
        "No space left on device"
    )
    # The control: the same user namespace without the limit.
    assert in_child(TRY, prefix=user_namespace_prefix(forbid=False)) is None


def test_a_namespace_error_names_its_step() -> None:
    error = NamespaceError("shm", errno.EPERM)
    assert (error.step, error.errno) == ("shm", errno.EPERM)
    assert error.strerror == "cannot mount a private tmpfs on /dev/shm: Operation not permitted"
    other = NamespaceError("somewhere else", errno.EIO)
    assert other.strerror == "cannot somewhere else: Input/output error"


#: ``enter_here`` in this very process: first while a thread runs (refused, nothing
#: entered), then alone. Prints what it saw before and after, and its capabilities.
ENTER = """
import json, os, socket, threading
from ros_isolated_test.process import namespace

def net():
    return os.readlink("/proc/self/ns/net")

def capabilities():
    for line in open("/proc/self/status"):
        if line.startswith("CapEff:"):
            return int(line.split()[1], 16)

found = {"before": net(), "threads_alone": namespace.threads()}
release = threading.Event()
thread = threading.Thread(target=release.wait)
thread.start()
found["threads_with_one"] = namespace.threads()
try:
    namespace.enter_here()
except namespace.NamespaceError as error:
    found["refused"] = [error.step, net()]
release.set()
thread.join()
while namespace.threads() > 1:
    pass
namespace.enter_here()
server = socket.socket()
server.bind(("127.0.0.1", 0))
server.listen(1)
socket.create_connection(server.getsockname()).close()
interfaces = [line.split(":")[0].strip() for line in open("/proc/net/dev").readlines()[2:]]
found.update(after=net(), interfaces=interfaces, user=namespace.describe_user(),
             capabilities=capabilities())
print(json.dumps(found))
"""


def test_enter_here_puts_this_process_in_them_and_refuses_while_threads_run() -> None:
    found = in_child(ENTER)
    assert (found["threads_alone"], found["threads_with_one"]) == (1, 2), found
    assert found["refused"] == ["threads", found["before"]], "refused, and nothing entered"
    assert found["after"] != found["before"] and found["interfaces"] == ["lo"], found
    assert found["user"] == f"uid {os.geteuid()}, gid {os.getegid()}"


@capabilities.OTHER_USERS.mark
def test_a_user_who_is_not_root_gives_back_the_capabilities_the_namespace_gave() -> None:
    """As nobody: none left, as after an exec; root (the control) keeps what it had."""
    nobody = user_keywords(65534)
    as_nobody = in_child(ENTER, **nobody)
    assert as_nobody["after"] != as_nobody["before"], as_nobody
    assert as_nobody["user"] == f"uid {nobody['user']}, gid {nobody['group']}"
    assert as_nobody["capabilities"] == 0, as_nobody
    assert os.geteuid() != 0 or in_child(ENTER)["capabilities"] != 0


#: Who the test is said to be in its user namespace.
DESCRIBE = """
import json
from ros_isolated_test.process import namespace
print(json.dumps(namespace.describe_user()))
"""


@capabilities.OTHER_USERS.mark
def test_the_user_is_described_with_the_groups_it_cannot_map() -> None:
    """A user without CAP_SETGID maps its gid alone: its groups read as 65534 inside.

    Controls: no supplementary groups, nothing to say; root holds CAP_SETGID and maps them.
    """
    nobody = user_keywords(65534)
    with_groups = in_child(DESCRIBE, **(nobody | {"extra_groups": [20, 44]}))
    assert with_groups == (
        "uid 65534, gid 65534 (supplementary groups 20, 44 read as 65534 there, granting as before)"
    )
    assert in_child(DESCRIBE, **nobody) == "uid 65534, gid 65534"
    assert in_child(DESCRIBE, extra_groups=[20, 44]) == "uid 0, gid 0"


# --- through the runner -----------------------------------------------------------------


def test_test_sees_its_own_network_shm_and_the_same_user(
    env: dict[str, str], tmp_path: Path, shm_name: str
) -> None:
    """Loopback only, up; a /dev/shm of its own; getuid(), $HOME unchanged."""
    name = shm_name
    done = run_cli(
        ["run", "--isolation", "namespace", "--junit-xml", str(tmp_path / "r.xml"),
         "--", sys.executable, "-c", LOOK, name],
        env,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    inside = seen(done.stdout)
    assert NAMESPACES in done.stdout.splitlines()[0], done.stdout
    assert inside["interfaces"] == ["lo"], inside
    assert inside["shm"] == [name], "the test's /dev/shm is not its own"
    assert not (Path("/dev/shm") / name).exists(), "the test's file reached the host's /dev/shm"
    assert (inside["uid"], inside["gid"]) == (os.getuid(), os.getgid())
    assert inside["home"] == env.get("HOME")
    assert inside["net"] != os.readlink("/proc/self/ns/net")
    properties = load_result(tmp_path / "r.xml").properties
    assert properties["isolation"] == "namespace"
    assert properties["ros_domain_id"] == inside["domain"]


def test_a_user_who_is_not_root_gets_them_as_that_user(
    env: dict[str, str], traversable_dir: Path, shm_name: str
) -> None:
    """The unprivileged case namespaces are for: nobody maps only its own uid and gid."""
    name = shm_name
    nobody = user_keywords(65534)
    done = run_process(
        [CLI, "run", "--isolation", "namespace", "--", sys.executable, "-c", LOOK, name],
        {**env, "ROS_ISOLATED_TEST_LOCK_DIR": str(traversable_dir / "locks"), "HOME": "/"},
        **nobody,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    inside = seen(done.stdout)
    assert (inside["uid"], inside["gid"]) == (nobody["user"], nobody["group"]), inside
    assert inside["interfaces"] == ["lo"] and inside["shm"] == [name], inside
    assert f"as uid {nobody['user']}, gid {nobody['group']}" in done.stdout, done.stdout


@capabilities.ROOT
def test_root_keeps_every_user_and_their_files(env: dict[str, str], tmp_path: Path) -> None:
    """Root maps every ID to itself: another user's file is still theirs, and readable.

    With only root mapped, the file would show the overflow uid and refuse root.
    """
    private = tmp_path / "daemons-file"
    private.write_text("daemon's")
    os.chown(private, 1, 1)
    private.chmod(0o600)
    look = "import os, sys; print(os.stat(sys.argv[1]).st_uid, open(sys.argv[1]).read())"
    done = run_cli(
        ["run", "--isolation", "namespace", "--", sys.executable, "-c", look, str(private)], env
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 daemon's" in done.stdout.splitlines(), done.stdout


def test_control_in_domain_mode_the_test_shares_the_hosts(
    env: dict[str, str], shm_name: str
) -> None:
    """The control: without namespaces the same command sees the host's network and /dev/shm."""
    done = run_cli(["run", "--", sys.executable, "-c", LOOK, shm_name], env)
    assert done.returncode == 0, done.stdout + done.stderr
    inside = seen(done.stdout)
    assert (Path("/dev/shm") / shm_name).exists(), "domain mode has a /dev/shm of its own?"
    assert inside["net"] == os.readlink("/proc/self/ns/net")
    assert NAMESPACES not in done.stdout


@pytest.mark.parametrize(("command", "code"), [(["no-such-command-rit"], 127), (["/"], 126)])
def test_a_command_that_cannot_start_in_namespaces_exits_as_without(
    env: dict[str, str], command: list[str], code: int
) -> None:
    done = run_cli(["run", "--isolation", "namespace", "--", *command], env)
    assert done.returncode == code, done.stdout + done.stderr
    assert "could not be started" in done.stdout, done.stdout
