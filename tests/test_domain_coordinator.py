"""The domain coordinator with real locks, sockets and processes.

Ports 32768+ID are machine-wide, so tests pick IDs whose port is free right now, from
215-232 where they can: outside the default pool and upstream's 1-100, so that other
runs on this machine rarely contend with them.
"""

from __future__ import annotations

import ast
import json
import os
import pwd
import signal
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, REPO, run_cli, run_runner
from helpers.domains import free_ids
from helpers.processes import DEADLINE, WAIT_SCRIPT, Children, user_keywords, wait_for
from helpers.results import result_error
from lxml import etree

from ros_isolated_test.domain_coordinator import (
    LOCK_DIR_ENV,
    POOL_ENV,
    DomainCoordinator,
    HeldDomain,
    LockDirError,
    PoolExhaustedError,
    held_domains,
    lock_dir_from_env,
)
from ros_isolated_test.domain_coordinator.lock_files import lock_path
from ros_isolated_test.domain_coordinator.port_guard import PORT_BASE, port_is_taken

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

# -- reserving and releasing --------------------------------------------------------------


def test_reserve_gives_the_first_free_id(lock_dir: Path) -> None:
    first, second, third = free_ids(3)
    coordinator = DomainCoordinator(lock_dir, (first, second, third))
    with coordinator.reserve(["test"]) as reservation:
        assert reservation.domain_id == first
    with DomainCoordinator(lock_dir, (third, first)).reserve(["test"]) as reservation:
        assert reservation.domain_id == third


def test_two_reservations_in_one_process_differ(lock_dir: Path) -> None:
    ids = free_ids(3)
    coordinator = DomainCoordinator(lock_dir, ids)
    with coordinator.reserve(["a"]) as one, coordinator.reserve(["b"]) as two:
        assert one.domain_id == ids[0]
        # Equally old IDs (none ever released here): which one comes next is the PID's.
        assert two.domain_id in ids[1:]
        with DomainCoordinator(lock_dir, ids).reserve(["c"]) as three:
            assert {one.domain_id, two.domain_id, three.domain_id} == set(ids)


def test_a_pool_with_every_id_held_is_exhausted(lock_dir: Path) -> None:
    ids = free_ids(2)
    coordinator = DomainCoordinator(lock_dir, ids)
    with coordinator.reserve(["a"]), coordinator.reserve(["b"]):
        assert coordinator.try_reserve(["c"]) is None
        with pytest.raises(PoolExhaustedError) as raised, coordinator.reserve(["c"]):
            pass
    message = str(raised.value)
    assert "all 2 IDs of the pool are in use" in message
    assert "ros-isolated-test status" in message
    assert POOL_ENV in message
    assert "\n" not in message


def test_run_with_the_pool_exhausted_exits_3_and_says_so(
    lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    ids = free_ids(2)
    marker = tmp_path / "ran"
    result_file = tmp_path / "out" / "exhausted.xml"
    env[POOL_ENV] = ",".join(map(str, ids))
    coordinator = DomainCoordinator(lock_dir, ids)
    with coordinator.reserve(["a"]), coordinator.reserve(["b"]):
        result = run_cli(
            [
                "run",
                "--wait-timeout",
                "0",
                "--junit-xml",
                str(result_file),
                "--",
                "touch",
                str(marker),
            ],
            env,
        )
    assert result.returncode == 3, result.stdout + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(
        "ros-isolated-test: error: no free ROS_DOMAIN_ID: all 2 IDs of the pool are in use"
    )
    assert not marker.exists()
    assert "all 2 IDs of the pool are in use" in result_error(result_file)


def test_release_makes_the_id_free_again(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    reservation = coordinator.try_reserve(["a"])
    assert reservation is not None
    assert coordinator.try_reserve(["b"]) is None
    assert port_is_taken(domain_id)
    reservation.release()
    assert reservation.released
    reservation.release()  # twice is harmless
    assert not port_is_taken(domain_id)
    again = coordinator.try_reserve(["c"])
    assert again is not None
    assert again.domain_id == domain_id
    again.release()


def test_leaving_the_block_by_an_exception_releases(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    with pytest.raises(KeyboardInterrupt), coordinator.reserve(["a"]):
        raise KeyboardInterrupt
    assert held_domains(lock_dir, (domain_id,)) == []
    with coordinator.reserve(["b"]) as reservation:
        assert reservation.domain_id == domain_id


def test_holder_record_is_written_then_removed(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    before = time.time()
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["my_test", "--flag"]) as reservation:
        record = reservation.record
        assert record == lock_dir / f"domain-{domain_id}.uid{os.getuid()}.holder.json"
        data = json.loads(record.read_text(encoding="utf-8"))
        assert data["domain_id"] == domain_id
        assert data["pid"] == os.getpid()
        assert data["user"] == pwd.getpwuid(os.getuid()).pw_name
        assert data["command"] == "my_test --flag"
        assert before <= data["started"] <= time.time()
        assert data["host"] == socket.gethostname()
        assert stat.S_IMODE(record.stat().st_mode) == 0o644
        (held,) = held_domains(lock_dir, (domain_id,))
        assert held.via == "lock"
        assert held.holder is not None
        assert held.holder.pid == os.getpid()
    assert not record.exists()
    assert not list(lock_dir.glob("*.json"))
    assert not list(lock_dir.glob(".*.tmp"))


def test_lock_file_stays_after_release_and_is_shared(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    path = lock_path(lock_dir, domain_id)
    old_umask = os.umask(0o077)
    try:
        with DomainCoordinator(lock_dir, (domain_id,)).reserve(["a"]):
            assert path.is_file()
            inode = path.stat().st_ino
    finally:
        os.umask(old_umask)
    assert path.is_file(), "the lock file must never be unlinked"
    assert path.stat().st_ino == inode
    assert stat.S_IMODE(path.stat().st_mode) == 0o666
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["b"]):
        assert path.stat().st_ino == inode
    assert path.stat().st_ino == inode


def test_a_created_lock_dir_is_mode_1777(lock_dir: Path) -> None:
    (domain_id,) = free_ids(1)
    fresh = lock_dir / "fresh"
    old_umask = os.umask(0o077)
    try:
        with DomainCoordinator(fresh, (domain_id,)).reserve(["a"]):
            pass
    finally:
        os.umask(old_umask)
    assert stat.S_IMODE(fresh.stat().st_mode) == 0o1777
    assert lock_path(fresh, domain_id).is_file()


def test_run_creates_a_missing_lock_dir_mode_1777(env: dict[str, str], lock_dir: Path) -> None:
    fresh = lock_dir / "made-by-run"
    env[LOCK_DIR_ENV] = str(fresh)
    result = run_cli(["run", "--", "true"], env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert stat.S_IMODE(fresh.stat().st_mode) == 0o1777
    assert list(fresh.glob("domain-*.lock"))


# -- where the lock directory is -----------------------------------------------------------


def test_default_lock_dir_is_one_fixed_path_under_tmp() -> None:
    default = lock_dir_from_env({})
    assert default == Path("/tmp/ros-isolated-test-domains")
    assert lock_dir_from_env({LOCK_DIR_ENV: "  "}) == default
    assert str(os.getuid()) not in default.name
    assert pwd.getpwuid(os.getuid()).pw_name not in default.name


def test_default_lock_dir_is_the_same_for_every_user(tmp_path: Path) -> None:
    """TMPDIR, HOME and USER differ per user; the default must not follow them."""
    code = "from ros_isolated_test.domain_coordinator import lock_dir_from_env as f; print(f())"
    base = {key: value for key, value in os.environ.items() if key != LOCK_DIR_ENV}
    seen = set()
    for name in ("alice", "bob"):
        private = tmp_path / name
        private.mkdir()
        env = {**base, "TMPDIR": str(private), "HOME": str(private), "USER": name}
        result = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
        )
        seen.add(result.stdout.strip())
    if os.getuid() == 0:
        capabilities.require(capabilities.OTHER_USERS)
        result = subprocess.run(
            [sys.executable, "-c", code],
            env={**base, "TMPDIR": str(tmp_path), "HOME": "/nonexistent", "USER": "nobody"},
            capture_output=True,
            text=True,
            check=True,
            user=65534,
            group=65534,
            extra_groups=[],
            cwd="/",
        )
        seen.add(result.stdout.strip())
    assert seen == {"/tmp/ros-isolated-test-domains"}


def test_lock_dir_override(lock_dir: Path, env: dict[str, str], tmp_path: Path) -> None:
    assert lock_dir_from_env({LOCK_DIR_ENV: "/srv/shared/locks"}) == Path("/srv/shared/locks")
    assert lock_dir_from_env() == lock_dir  # conftest points the variable at the test's dir
    assert DomainCoordinator().lock_dir == lock_dir
    elsewhere = tmp_path / "elsewhere"
    env[LOCK_DIR_ENV] = str(elsewhere)
    result = run_cli(["run", "--", "sh", "-c", 'echo "id=$ROS_DOMAIN_ID"'], env)
    assert result.returncode == 0, result.stdout + result.stderr
    (line,) = [line for line in result.stdout.splitlines() if line.startswith("id=")]
    assert lock_path(elsewhere, int(line[3:])).is_file()
    assert not list(lock_dir.iterdir())


def test_a_lock_dir_that_is_a_file_is_a_clear_error(tmp_path: Path, env: dict[str, str]) -> None:
    (domain_id,) = free_ids(1)
    path = tmp_path / "not-a-dir"
    path.write_text("x")
    with pytest.raises(LockDirError) as raised:
        DomainCoordinator(path, (domain_id,)).try_reserve(["a"])
    message = str(raised.value)
    assert str(path) in message
    assert "not a directory" in message
    assert LOCK_DIR_ENV in message
    assert "\n" not in message

    env[LOCK_DIR_ENV] = str(path)
    result_file = tmp_path / "result.xml"
    marker = tmp_path / "ran"
    result = run_cli(["run", "--junit-xml", str(result_file), "--", "touch", str(marker)], env)
    assert result.returncode == 3, result.stdout + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert str(path) in lines[0]
    assert not marker.exists()
    assert str(path) in result_error(result_file)
    assert path.read_text() == "x"


def test_a_lock_dir_whose_parent_is_missing_is_a_clear_error(tmp_path: Path) -> None:
    (domain_id,) = free_ids(1)
    path = tmp_path / "missing" / "locks"
    with pytest.raises(LockDirError) as raised:
        DomainCoordinator(path, (domain_id,)).try_reserve(["a"])
    assert str(path) in str(raised.value)
    assert LOCK_DIR_ENV in str(raised.value)


# -- holders that die ----------------------------------------------------------------------


def test_a_sigkilled_holder_frees_its_id_at_once(lock_dir: Path, children: Children) -> None:
    (domain_id,) = free_ids(1)
    child = children.python(HOLD_SCRIPT, lock_dir, domain_id)
    assert children.first_line(child) == str(domain_id)
    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    assert coordinator.try_reserve(["parent"]) is None
    (held,) = held_domains(lock_dir, (domain_id,))
    assert held.holder is not None
    assert held.holder.pid == child.pid

    os.kill(child.pid, signal.SIGKILL)
    assert child.wait(timeout=DEADLINE) == -signal.SIGKILL
    # The killed child left its holder record behind; the lock is what counts.
    assert held_domains(lock_dir, (domain_id,)) == []
    reservation = coordinator.try_reserve(["parent"])
    assert reservation is not None
    assert reservation.domain_id == domain_id
    reservation.release()


def test_a_sigkilled_runner_frees_its_lock_and_port_but_its_test_still_blocks_the_id(
    lock_dir: Path, env: dict[str, str], tmp_path: Path, children: Children
) -> None:
    """Neither the lock nor the port leaks into the test process the runner started, but
    the orphaned test still talks on the domain: the squatter scan keeps the ID out of use.
    """
    (domain_id,) = free_ids(1)
    env[POOL_ENV] = str(domain_id)
    pid_file, go = tmp_path / "test.pid", tmp_path / "go"
    runner = children.start(
        [CLI, "run", "--", sys.executable, "-c", WAIT_SCRIPT, str(pid_file), str(go)], env=env
    )
    wait_for(pid_file)
    test_pid = int(pid_file.read_text())
    try:
        assert port_is_taken(domain_id)
        assert DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"]) is None
        os.kill(runner.pid, signal.SIGKILL)
        assert runner.wait(timeout=DEADLINE) == -signal.SIGKILL
        os.kill(test_pid, 0)  # the test process is still running
        assert not port_is_taken(domain_id)
        assert DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"]) is None
        go.touch()
        deadline = time.monotonic() + DEADLINE
        while time.monotonic() < deadline:
            reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["x"])
            if reservation is not None:
                reservation.release()
                break
            time.sleep(0.05)
        else:
            pytest.fail("the ID stayed blocked after the orphan ended")
    finally:
        go.touch()


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
    ours = [
        item for item in held_domains(lock_dir, (upstream_id,)) if item.domain_id == upstream_id
    ]
    assert ours == [HeldDomain(upstream_id, "port", None)]
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
    assert held_domains(lock_dir, (taken,)) == [HeldDomain(taken, "port", None)]
    assert children.finish(binder) == 0
    with DomainCoordinator(lock_dir, (taken,)).reserve(["a"]) as reservation:
        assert reservation.domain_id == taken


# -- status beyond the current pool and lock dir ------------------------------------------


def test_status_lists_an_id_held_outside_the_callers_pool(
    lock_dir: Path, env: dict[str, str]
) -> None:
    """Another user's runner may have a pool of its own; its IDs are still held here."""
    (domain_id,) = free_ids(1)
    with DomainCoordinator(lock_dir, (domain_id,)).reserve(["other_pool_test"]):
        result = run_cli(["status", "--json"], env)  # the default pool, 1-101
    assert result.returncode == 0, result.stderr
    rows = [row for row in json.loads(result.stdout) if row["via"] == "lock"]
    assert [(row["domain_id"], row["pid"]) for row in rows] == [(domain_id, os.getpid())]


def test_status_lists_upstream_holders_before_any_runner_made_the_lock_dir(
    lock_dir: Path, env: dict[str, str], children: Children
) -> None:
    # Upstream's first free ID, and no squatter's (upstream does not look): status must
    # name upstream's port alone.
    upstream = children.python(UPSTREAM_SCRIPT, *free_ids(1, range(1, 101)))
    upstream_id = int(children.first_line(upstream))
    missing = lock_dir / "not-made-yet"
    assert held_domains(missing, (upstream_id,)) == [HeldDomain(upstream_id, "port", None)]
    env[LOCK_DIR_ENV] = str(missing)
    env[POOL_ENV] = str(upstream_id)
    result = run_cli(["status", "--json"], env)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == [{"domain_id": upstream_id, "via": "port"}]
    assert not missing.exists()


# -- the runner never loads upstream's top-level domain_coordinator ------------------------


def _upstream_imports(text: str, label: str) -> list[str]:
    """Where ``text`` imports upstream's top-level ``domain_coordinator``, as label:line."""
    found = []
    for node in ast.walk(ast.parse(text, filename=label)):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            names = [str(node.args[0].value)]
        found += [
            f"{label}:{getattr(node, 'lineno', '?')}: {name}"
            for name in names
            if name == "domain_coordinator" or name.startswith("domain_coordinator.")
        ]
    return found


def test_control_the_import_scan_finds_every_way_to_import_upstream() -> None:
    text = (
        "import domain_coordinator\n"
        "from domain_coordinator import domain_id\n"
        "import importlib; importlib.import_module('domain_coordinator.impl')\n"
        "from ros_isolated_test.domain_coordinator import POOL_ENV\n"
        "from .domain_coordinator import pool\n"
        "from . import domain_coordinator\n"
    )
    assert _upstream_imports(text, "x.py") == [
        "x.py:1: domain_coordinator",
        "x.py:2: domain_coordinator",
        "x.py:3: domain_coordinator.impl",
    ]


def test_no_source_file_imports_the_top_level_domain_coordinator() -> None:
    package = REPO / "ros_isolated_test"
    sources = sorted(package.rglob("*.py"))
    assert len(sources) > 10
    offenders = []
    for source in sources:
        label = str(source.relative_to(REPO))
        offenders += _upstream_imports(source.read_text(encoding="utf-8"), label)
    assert offenders == []


@pytest.fixture
def poisoned_env(env: dict[str, str], tmp_path: Path) -> dict[str, str]:
    """A sourced ROS setup puts upstream's domain_coordinator first; this one explodes."""
    fake = tmp_path / "fake_ros" / "domain_coordinator"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(
        "raise RuntimeError('upstream domain_coordinator must not be imported')\n"
    )
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(fake.parent), env.get("PYTHONPATH")]))
    probe = subprocess.run(
        [sys.executable, "-c", "import domain_coordinator"],
        check=False,
        env=env,
        capture_output=True,
        text=True,
    )
    assert probe.returncode != 0
    assert "must not be imported" in probe.stderr
    return env


def test_run_works_with_a_poisoned_domain_coordinator_first_on_pythonpath(
    poisoned_env: dict[str, str], tmp_path: Path
) -> None:
    result_file = tmp_path / "result.xml"
    result = run_cli(["run", "--junit-xml", str(result_file), "--", "true"], poisoned_env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Running with ROS_DOMAIN_ID" in result.stdout
    assert "must not be imported" not in result.stdout + result.stderr
    assert not etree.parse(str(result_file)).getroot().findall(".//error")
    status = run_cli(["status", "--json"], poisoned_env)
    assert status.returncode == 0, status.stderr


def test_ctest_runner_works_with_a_poisoned_domain_coordinator_first_on_pythonpath(
    poisoned_env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    result_file = tmp_path / "pkg" / "t.xml"
    args = [str(result_file), "--package-name", "pkg", "--generate-result-on-success"]
    result = run_runner(runner_script, [*args, "--command", "true"], poisoned_env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Running with ROS_DOMAIN_ID" in result.stdout
    assert "must not be imported" not in result.stdout + result.stderr


# -- every user on the machine shares the lock directory -----------------------------------


def test_users_share_lock_files_and_the_lock_dir(traversable_dir: Path, children: Children) -> None:
    nobody, daemon = 65534, 1  # traversable_dir requires both users
    first, second = free_ids(2)
    lock_dir = traversable_dir / "locks"

    # nobody creates the lock dir and the lock file of `first`, under umask 077.
    by_nobody = children.python(HOLD_SCRIPT, lock_dir, first, **user_keywords(nobody))
    assert children.first_line(by_nobody) == str(first)
    assert lock_dir.stat().st_uid == nobody
    assert stat.S_IMODE(lock_dir.stat().st_mode) == 0o1777
    assert lock_path(lock_dir, first).stat().st_uid == nobody
    assert stat.S_IMODE(lock_path(lock_dir, first).stat().st_mode) == 0o666

    # daemon, another user, finds `first` held by nobody and takes `second`.
    by_daemon = children.python(HOLD_SCRIPT, lock_dir, first, second, **user_keywords(daemon))
    assert children.first_line(by_daemon) == str(second)
    held = {item.domain_id: item for item in held_domains(lock_dir, (first, second))}
    assert set(held) == {first, second}
    first_holder, second_holder = held[first].holder, held[second].holder
    assert first_holder is not None and second_holder is not None
    assert (first_holder.user, first_holder.pid) == ("nobody", by_nobody.pid)
    assert (second_holder.user, second_holder.pid) == ("daemon", by_daemon.pid)
    assert DomainCoordinator(lock_dir, (first, second)).try_reserve(["root"]) is None

    assert children.finish(by_nobody) == 0
    assert children.finish(by_daemon) == 0
    assert held_domains(lock_dir, (first, second)) == []
    # daemon can now lock the file nobody created, and nobody the one daemon created.
    swapped = children.python(HOLD_SCRIPT, lock_dir, first, **user_keywords(daemon))
    assert children.first_line(swapped) == str(first)
    assert children.finish(swapped) == 0
    swapped = children.python(HOLD_SCRIPT, lock_dir, second, **user_keywords(nobody))
    assert children.first_line(swapped) == str(second)
    assert children.finish(swapped) == 0


def test_an_unwritable_lock_file_of_another_user_does_not_lock_everyone_out(
    traversable_dir: Path,
) -> None:
    """Only its owner can remove it from the sticky dir: failing on it stops every run.

    The rest of the pool is free, and a flock needs no write access to the file.
    """
    nobody, daemon = 65534, 1
    first, second = free_ids(2)
    lock_dir = traversable_dir / "locks"
    lock_dir.mkdir(mode=0o1777)
    os.chmod(lock_dir, 0o1777)
    stray = lock_path(lock_dir, first)
    stray.touch(mode=0o600)
    os.chown(stray, nobody, -1)
    os.chmod(stray, 0o600)
    env = {
        **{key: value for key, value in os.environ.items() if key != "ROS_DOMAIN_ID"},
        LOCK_DIR_ENV: str(lock_dir),
        POOL_ENV: f"{first},{second}",
    }
    result = subprocess.run(
        [CLI, "run", "--", "sh", "-c", 'echo "id=$ROS_DOMAIN_ID"'],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        **user_keywords(daemon),
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "id=" in result.stdout


PLANTED = ["dangling symlink", "symlink to a directory", "directory"]


def plant(planted: str, path: Path, tmp_path: Path) -> None:
    """Anyone may create entries in the shared (1777) lock dir, at any ID's lock path."""
    if planted == "dangling symlink":
        path.symlink_to(tmp_path / "nowhere")
    elif planted == "symlink to a directory":
        path.symlink_to(tmp_path)
    else:
        path.mkdir()


@pytest.mark.parametrize("planted", PLANTED)
def test_something_planted_at_a_lock_path_does_not_deny_the_id(
    planted: str, lock_dir: Path, tmp_path: Path
) -> None:
    """The runner falls back to a lock file of its own; the port keeps holders apart."""
    first, second = free_ids(2)
    path = lock_path(lock_dir, first)
    plant(planted, path, tmp_path)
    reservation = DomainCoordinator(lock_dir, (first, second)).try_reserve(["a"])
    assert reservation is not None
    assert reservation.domain_id == first
    assert port_is_taken(first)
    assert DomainCoordinator(lock_dir, (first,)).try_reserve(["b"]) is None
    reservation.release()
    assert not (tmp_path / "nowhere").exists(), "a planted symlink was followed"


@pytest.mark.parametrize("planted", PLANTED)
def test_something_planted_at_a_lock_path_does_not_crash_the_cli(
    planted: str, lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    """Skip the ID or refuse clearly (exit 3); never a traceback with a failed test's code."""
    first, second = free_ids(2)
    path = lock_path(lock_dir, first)
    plant(planted, path, tmp_path)
    env[POOL_ENV] = f"{first},{second}"
    result_file = tmp_path / "result.xml"
    result = run_cli(["run", "--junit-xml", str(result_file), "--", "true"], env)
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode in (0, 3), result.stdout + result.stderr
    if result.returncode == 3:
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert len(lines) == 1, result.stderr
        assert str(path) in lines[0]
        assert str(path) in result_error(result_file)

    status = run_cli(["status"], env)
    assert "Traceback" not in status.stderr, status.stderr
    assert status.returncode == 0, status.stderr
