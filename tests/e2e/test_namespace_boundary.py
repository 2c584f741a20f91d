"""The namespace boundary, measured: what crosses it, what it hides, who the test is inside.

Each claim docs/isolation.md and the runner's note make about namespace mode has a test
here, and each runs beside its control, domain mode, where the same probe reaches the
host. The probe (``helpers.boundary``) runs once per mode through ``run``, with the host's
end of every channel open in this process: TCP, UDP and multicast on loopback, abstract
and path-bound Unix sockets, files in /dev/shm and elsewhere, System V and POSIX IPC, and
what /proc shows. Then what the private /dev/shm would hide: a test that starts there, or
is handed a path there, is refused up front (``auto`` falls back), through ``run``, the
RUNNER and the pytest plugin, each beside the same test from a folder on disk. Last, the
supplementary groups: read as themselves where the runner may map them, else as the
overflow group, with the access they grant unchanged.
"""

from __future__ import annotations

import os
import shutil
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from helpers import capabilities
from helpers.boundary import PROBE, HostSide, reported
from helpers.commands import (
    CLI,
    ERROR_PREFIX,
    ament_args,
    run_cli,
    run_process,
    run_runner,
    the_error_line,
)
from helpers.namespaces import ISOLATION, NAMESPACES
from helpers.results import load_result

pytestmark = [capabilities.UNSHARE.mark]

MODES = ("namespace", "domain")


# --- 1. what crosses the boundary ---------------------------------------------------------


@pytest.fixture(scope="module")
def reached(module_env: dict[str, str]) -> dict[str, dict[str, Any]]:
    """What the probe reached of the host, per mode (and the runner's output, ``output``)."""
    found = {}
    for mode in MODES:
        with HostSide() as host:
            done = run_cli(
                ["run", "--isolation", mode, "--", sys.executable, "-c", PROBE, host.spec],
                module_env,
            )
            assert done.returncode == 0, done.stdout + done.stderr
            seen = reported(done.stdout)
            seen.update(host.heard())
            seen["shm_reached_host"] = host.test_wrote_into_the_hosts_shm()
            seen["output"] = done.stdout
        found[mode] = seen
    return found


def both(reached: dict[str, dict[str, Any]], key: str) -> tuple[Any, Any]:
    """(namespace, domain): what the probe found of ``key`` in each mode."""
    return reached["namespace"][key], reached["domain"][key]


def test_tcp_to_the_hosts_loopback_does_not_cross(reached: dict[str, dict[str, Any]]) -> None:
    """A server on the host's 127.0.0.1 is out of reach: the test's loopback is its own."""
    assert both(reached, "tcp") == (False, True)


def test_udp_to_the_hosts_loopback_does_not_cross(reached: dict[str, dict[str, Any]]) -> None:
    assert both(reached, "udp") == (False, True)


def test_multicast_stays_inside_and_does_not_reach_the_hosts_group(
    reached: dict[str, dict[str, Any]],
) -> None:
    """A datagram to a group joined on loopback: the test's own group hears it, the host's not."""
    assert both(reached, "own_multicast") == (True, True)
    assert both(reached, "multicast") == (False, True)


def test_an_abstract_unix_socket_does_not_cross(reached: dict[str, dict[str, Any]]) -> None:
    """Abstract names belong to the network namespace."""
    assert both(reached, "abstract_unix") == (False, True)


def test_a_unix_socket_bound_to_a_path_crosses(reached: dict[str, dict[str, Any]]) -> None:
    """Not isolated: a path is a file, and the file system is the host's."""
    assert both(reached, "path_unix") == (True, True)


def test_files_outside_dev_shm_are_the_hosts(reached: dict[str, dict[str, Any]]) -> None:
    """Not isolated: no mount but /dev/shm is replaced."""
    assert both(reached, "file") == ("the host's file", "the host's file")


def test_dev_shm_is_private_both_ways(reached: dict[str, dict[str, Any]]) -> None:
    """The host's file is not seen inside, and the test's never reaches the host's."""
    assert both(reached, "shm_file") == ("FileNotFoundError", "the host's")
    assert both(reached, "shm_reached_host") == (False, True)


def test_system_v_shared_memory_does_not_cross(reached: dict[str, dict[str, Any]]) -> None:
    assert both(reached, "sysv_shm") == (False, True)


def test_posix_message_queues_do_not_cross(reached: dict[str, dict[str, Any]]) -> None:
    assert both(reached, "posix_mq") == (False, True)


def test_proc_shows_the_hosts_processes_and_its_runners_socket_table(
    reached: dict[str, dict[str, Any]],
) -> None:
    """Not isolated (no PID namespace): every host process is in /proc, and /proc/$PPID/net
    is the runner's network, the host's: its listener is listed, read only (not reached)."""
    assert both(reached, "host_process") == (True, True)
    assert both(reached, "parent_net_tcp") == (True, True)
    assert both(reached, "own_net_tcp") == (False, True), "its own table lists its own only"


def test_signals_reach_the_hosts_processes_of_its_user(reached: dict[str, dict[str, Any]]) -> None:
    """Not isolated: kill(2) to a process of the same user outside succeeds."""
    assert both(reached, "signal_host") == (True, True)


def test_the_runners_root_in_proc_is_out_of_reach(reached: dict[str, dict[str, Any]]) -> None:
    """/proc/$PPID/root would lead to the host's /dev/shm: the kernel refuses it from inside."""
    assert both(reached, "parent_root_shm") == (False, True)


def test_the_note_says_what_is_and_is_not_isolated(reached: dict[str, dict[str, Any]]) -> None:
    output = reached["namespace"]["output"]
    notes = [line for line in output.splitlines() if "isolation namespace:" in line]
    assert len(notes) == 1, output
    (note,) = notes
    for isolated in ("ports", "multicast", "abstract Unix sockets", "/dev/shm and IPC"):
        assert isolated in note.split("are its own")[0], note
    assert "a Unix socket bound to a path" in note and "shared with the host" in note, note
    assert "nothing it binds" not in note
    assert "isolation namespace" not in reached["domain"]["output"]


# --- 2. what the private /dev/shm would hide ----------------------------------------------

#: A pytest file reading a file beside it: fails when the folder is out of its reach.
TEST_FILE = 'def test_a():\n    assert open("data.txt").read() == "data"\n'


def make_folder(root: Path) -> Path:
    """A test's folder under ``root``: its pytest file, its data, a shell test."""
    folder = root / f"rit-ws-{uuid.uuid4().hex[:12]}"
    folder.mkdir()
    (folder / "test_x.py").write_text(TEST_FILE)
    (folder / "data.txt").write_text("data")
    script = folder / "t.sh"
    script.write_text('#!/bin/sh\ntouch "$1"\n')
    script.chmod(0o755)
    return folder


@pytest.fixture
def in_shm() -> Iterator[Path]:
    """A test's folder in the host's /dev/shm, removed after."""
    folder = make_folder(Path("/dev/shm"))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


#: How a test is handed its folder, and what the refusal names then.
HANDED = ("working-directory", "command", "argument")


def handed(how: str, folder: Path, marker: Path) -> tuple[Path, list[str], str]:
    """(where the test starts, its command, what a refusal names): it touches ``marker``."""
    if how == "working-directory":
        run_pytest = f'touch {marker}; exec "$0" -m pytest -p no:cacheprovider -q test_x.py'
        command = ["sh", "-c", run_pytest, sys.executable]
        return folder, command, f"its working directory {folder}"
    if how == "command":
        return Path("/"), [str(folder / "t.sh"), str(marker)], f"its command {folder}/t.sh"
    data = folder / "data.txt"
    command = ["sh", "-c", f'touch {marker}; exec cat "$0"', str(data)]
    return Path("/"), command, f"its argument {data}"


@pytest.mark.parametrize("how", HANDED)
@pytest.mark.parametrize("where", ["dev-shm", "control-on-disk"])
def test_a_test_in_the_hosts_dev_shm_is_refused_before_anything_runs(
    env: dict[str, str], tmp_path: Path, in_shm: Path, how: str, where: str
) -> None:
    """One line naming the private /dev/shm, the path and the fix; exit 2; a result file.

    Without the refusal the test ran and failed: pytest with "file or directory not
    found" and a traceback, the command not found. The control is the same test in a
    folder on disk: it runs and passes in namespaces.
    """
    folder = in_shm if where == "dev-shm" else make_folder(tmp_path)
    marker = tmp_path / "ran"
    cwd, command, named = handed(how, folder, marker)
    result = tmp_path / "r.xml"
    done = run_cli(
        ["run", "--isolation", "namespace", "--junit-xml", str(result), "--", *command],
        env,
        cwd=cwd,
    )
    if where != "dev-shm":
        assert done.returncode == 0, done.stdout + done.stderr
        assert NAMESPACES in done.stdout.splitlines()[0] and marker.exists(), done.stdout
        return
    line = the_error_line(done)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "gives the test a /dev/shm of its own (a private tmpfs, empty)" in line, line
    assert "in the host's /dev/shm, out of its reach; move the test's files out of" in line
    assert named in line, line
    assert not marker.exists(), "the test ran"
    summary = load_result(result)
    assert summary.only.outcome == "failure"
    assert summary.only.message == line.removeprefix(ERROR_PREFIX)
    assert summary.properties["exit"] == "not run"


def test_the_runner_refuses_a_workspace_in_dev_shm_and_runs_one_on_disk(
    env: dict[str, str], runner_script: str, tmp_path: Path, in_shm: Path
) -> None:
    """The RUNNER, as ctest calls it in a build folder: the result file it names the test
    writes, the package's PYTHONPATH, the working directory; and the control on disk."""
    for folder in (in_shm, make_folder(tmp_path)):
        result = folder / "test_results" / "pkg" / "t.xml"
        result.parent.mkdir(parents=True)
        pytest_command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q",
                          f"--junit-xml={result}", "test_x.py"]  # fmt: skip
        args = ament_args(result, pytest_command, "--env", f"{ISOLATION}=namespace")
        pythonpath = {**env, "PYTHONPATH": str(folder)}
        done = run_runner(runner_script, args, pythonpath, cwd=folder)
        if folder != in_shm:
            assert done.returncode == 0, done.stdout + done.stderr
            assert load_result(result).only.outcome == "passed"
            continue
        line = the_error_line(done)
        assert done.returncode == 2, done.stdout + done.stderr
        named = (
            f"its working directory {folder}, its result file {result} (the test writes it), "
            "its argument test_x.py and 1 more are in the host's /dev/shm"  # PYTHONPATH's
        )
        assert named in line, line
        summary = load_result(result)
        assert summary.only.message == line.removeprefix(ERROR_PREFIX)
        assert summary.properties["exit"] == "not run"


def test_auto_runs_a_test_in_dev_shm_on_the_domain_id_alone_and_says_why(
    env: dict[str, str], in_shm: Path
) -> None:
    command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "test_x.py"]
    done = run_cli(["run", "--isolation", "auto", "--", *command], env, cwd=in_shm)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "isolation auto: by the domain ID alone" in done.stdout.splitlines()[0]
    why = f"as namespaces would cut it off: its working directory {in_shm}"
    assert why in done.stdout and "1 passed" in done.stdout, done.stdout


@pytest.mark.parametrize(
    "given",
    ["output-file", "result-file-the-runner-writes", "a-name-the-test-makes", "tmpdir-dev-shm"],
)
def test_control_what_the_test_never_reaches_in_dev_shm_is_not_refused(
    env: dict[str, str], tmp_path: Path, in_shm: Path, given: str
) -> None:
    """The runner's own files are written outside; a name not there yet, and /dev/shm
    itself, are the test's own inside: all run in namespaces."""
    name = f"rit-segment-{uuid.uuid4().hex}"
    options, command, extra = [], ["true"], {}
    if given == "output-file":
        options = ["--output-file", str(in_shm / "out.log")]
    elif given == "result-file-the-runner-writes":
        options = ["--junit-xml", str(in_shm / "r.xml")]
    elif given == "a-name-the-test-makes":
        command = ["sh", "-c", 'echo made > "$0" && cat "$0"', f"/dev/shm/{name}"]
    else:
        extra = {"TMPDIR": "/dev/shm"}
        command = [sys.executable, "-c", "import tempfile; tempfile.mkstemp()"]
    done = run_cli(["run", "--isolation", "namespace", *options, "--", *command], {**env, **extra})
    assert done.returncode == 0, done.stdout + done.stderr
    assert not (Path("/dev/shm") / name).exists(), "the test's name reached the host's /dev/shm"
    if given == "output-file":
        assert NAMESPACES in (in_shm / "out.log").read_text()
    if given == "result-file-the-runner-writes":
        assert load_result(in_shm / "r.xml").only.outcome == "passed"


@pytest.mark.parametrize("where", ["dev-shm", "control-on-disk"])
def test_a_pytest_session_in_dev_shm_is_pytests_usage_error(
    env: dict[str, str], tmp_path: Path, in_shm: Path, where: str
) -> None:
    folder = in_shm if where == "dev-shm" else make_folder(tmp_path)
    done = run_process(
        [sys.executable, "-m", "pytest", "--ros-isolation", "-p", "no:cacheprovider", "-q",
         "test_x.py"],
        {**env, ISOLATION: "namespace"},
        cwd=folder,
    )  # fmt: skip
    if where != "dev-shm":
        assert done.returncode == 0, done.stdout + done.stderr
        return
    assert done.returncode == 4, done.stdout + done.stderr
    assert f"its working directory {folder} is in the host's /dev/shm" in done.stderr


# --- 3. who the test is: supplementary groups ------------------------------------------------

#: Prints the test's groups and whether it can read a file only group 44 may read.
GROUPS = (
    "import os, sys\n"
    "try:\n    readable = open(sys.argv[1]).read() == 'secret'\n"
    "except OSError:\n    readable = False\n"
    "print('GROUPS', sorted(os.getgroups()), readable)"
)
EXTRA_GROUPS = "20,44"
AS_NOBODY = ["--reuid=65534", "--regid=65534"]
#: setpriv's words for each runner: root, nobody, nobody holding CAP_SETGID.
USERS = {
    "root": [],
    "nobody": AS_NOBODY,
    "nobody-with-cap-setgid": [*AS_NOBODY, "--inh-caps=+setgid", "--ambient-caps=+setgid"],
}


def groups_seen(
    env: dict[str, str], shared: Path, user: str, mode: str, groups: str = EXTRA_GROUPS
) -> tuple[str, str]:
    """(what the test printed, the runner's output) for a runner started as ``user``."""
    secret = shared / "group-44-only"
    if not secret.exists():
        secret.write_text("secret")
        os.chown(secret, 0, 44)
        secret.chmod(0o640)
    done = run_process(
        ["setpriv", *USERS[user], f"--groups={groups}", CLI, "run", "--isolation", mode,
         "--", sys.executable, "-c", GROUPS, str(secret)],
        {**env, "ROS_ISOLATED_TEST_LOCK_DIR": str(shared / "locks"), "HOME": "/"},
        cwd="/",
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    printed = [line for line in done.stdout.splitlines() if line.startswith("GROUPS ")]
    assert len(printed) == 1, done.stdout
    return printed[0], done.stdout


@capabilities.SETPRIV.mark
@pytest.mark.parametrize("user", ["root", "nobody-with-cap-setgid"])
def test_supplementary_groups_are_kept_where_the_runner_may_map_them(
    env: dict[str, str], traversable_dir: Path, user: str
) -> None:
    """CAP_SETGID lets the runner map every group to itself: getgroups() as in domain mode."""
    in_domain, _output = groups_seen(env, traversable_dir, user, "domain")
    assert in_domain == "GROUPS [20, 44] True"
    inside, output = groups_seen(env, traversable_dir, user, "namespace")
    assert inside == in_domain, output
    assert "read as" not in output, output


@capabilities.SETPRIV.mark
def test_a_user_without_cap_setgid_sees_them_as_the_overflow_group_with_their_access(
    env: dict[str, str], traversable_dir: Path
) -> None:
    """The kernel lets a user map one gid, setgroups denied: the groups read as 65534, the
    note says so, and what group 44 may read it still reads (control: without group 44,
    it may not, in either mode)."""
    in_domain, _output = groups_seen(env, traversable_dir, "nobody", "domain")
    assert in_domain == "GROUPS [20, 44] True"
    inside, output = groups_seen(env, traversable_dir, "nobody", "namespace")
    assert inside == "GROUPS [65534, 65534] True", output
    said = "as uid 65534, gid 65534 (supplementary groups 20, 44 read as 65534 there"
    assert said in output, output
    for mode in MODES:
        without, _output = groups_seen(env, traversable_dir, "nobody", mode, groups="20")
        assert without.endswith("False"), (mode, without)
