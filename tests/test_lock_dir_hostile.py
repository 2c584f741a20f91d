"""A lock directory shared by all users is hostile ground (issue item 7).

Anyone may create entries in a mode-1777 directory, at any name a runner uses. Whatever
is planted there, the runner never follows a symlink, never writes or replaces a file it
does not own, still gets its ID, and otherwise fails with exit 3, one line naming the
path and the fix, and a result file saying the same.

The root-owned planted entries sit in pytest's private (non-sticky) directories on
purpose: fs.protected_symlinks/protected_regular only guard sticky world-writable
directories, so there a runner that followed a link would really reach its target.
"""

from __future__ import annotations

import os
import random
import shlex
import shutil
import socket
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI
from helpers.domains import HIGH_IDS, free_ids
from helpers.processes import DEADLINE, WAIT_SCRIPT, Children, user_keywords, wait_for
from helpers.results import result_error

from ros_isolated_test.domain_coordinator import (
    LOCK_DIR_ENV,
    POOL_ENV,
    DomainCoordinator,
    held_domains,
)
from ros_isolated_test.domain_coordinator.holder import record_path
from ros_isolated_test.domain_coordinator.lock_files import lock_path, own_lock_path
from ros_isolated_test.domain_coordinator.reservation import release_stamp

NOBODY, DAEMON = 65534, 1
#: A run that takes longer than this is hanging (on a FIFO, a lock, a mount).
HANG = 10.0
PRINT_ID = 'echo "id=$ROS_DOMAIN_ID"'
#: Long ago, so that any touch by the runner shows.
OLD_MTIME_NS = 978_307_200 * 10**9


# -- helpers --------------------------------------------------------------------------------


def pick_ids(count: int) -> list[int]:
    """Free IDs in random order: other test runs on this machine start at the lowest."""
    return free_ids(count, random.sample(HIGH_IDS, len(HIGH_IDS)))


def snapshot(path: Path) -> tuple[object, ...]:
    """Everything the runner could change about an entry without following it."""
    info = os.lstat(path)
    content: object = None
    if stat.S_ISREG(info.st_mode):
        content = path.read_bytes()
    elif stat.S_ISLNK(info.st_mode):
        content = os.readlink(path)
    return (info.st_mode, info.st_uid, info.st_gid, info.st_ino, info.st_mtime_ns, content)


def tree(root: Path) -> dict[str, tuple[object, ...]]:
    """Snapshots of every entry under ``root`` (itself excluded), links not followed."""
    found: dict[str, tuple[object, ...]] = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder, name)
            found[str(path.relative_to(root))] = snapshot(path)
    return found


def assert_unchanged(path: Path, before: tuple[object, ...]) -> None:
    assert os.path.lexists(path), f"{path} was removed or replaced by the runner"
    assert snapshot(path) == before, f"{path} was changed by the runner"


def plant_file(path: Path, owner: int, mode: int, content: bytes = b"planted\n") -> None:
    """Owned by ``owner`` when we are root; otherwise by us (the tests that need it skip)."""
    path.write_bytes(content)
    if os.getuid() == 0:
        os.chown(path, owner, owner)
    os.chmod(path, mode)
    os.utime(path, ns=(OLD_MTIME_NS, OLD_MTIME_NS))


def run_timed(
    args: list[str], env: dict[str, str], timeout: float = HANG, **kwargs: object
) -> subprocess.CompletedProcess[str]:
    """``ros-isolated-test ARGS``; a run that outlives ``timeout`` fails the test as a hang."""
    try:
        return subprocess.run(  # type: ignore[call-overload, no-any-return]
            [CLI, *args],
            check=False,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            **kwargs,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"ros-isolated-test {shlex.join(args)} hung: killed after {timeout} s")


def granted_id(result: subprocess.CompletedProcess[str]) -> int:
    """The ID the test command saw, from its ``id=`` line; fails with the run's output."""
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    (line,) = [line for line in result.stdout.splitlines() if line.startswith("id=")]
    return int(line[3:])


def error_line(result: subprocess.CompletedProcess[str]) -> str:
    """Exit 3 and exactly one error line on stderr, which is returned."""
    assert result.returncode == 3, result.stdout + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("ros-isolated-test: error: "), lines[0]
    return lines[0]


def shared_env(env: dict[str, str], lock_dir: Path, *pool: int) -> dict[str, str]:
    return {**env, LOCK_DIR_ENV: str(lock_dir), POOL_ENV: ",".join(map(str, pool))}


@pytest.fixture
def shared_lock_dir(traversable_dir: Path) -> Path:
    """A mode-1777 lock directory that the users nobody and daemon can reach."""
    path = traversable_dir / "locks"  # traversable_dir requires the users nobody and daemon
    path.mkdir()
    os.chmod(path, 0o1777)
    return path


def as_user(uid: int, args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return run_timed(args, env, **user_keywords(uid))


# -- a lock file another user planted -------------------------------------------------------


def test_a_lock_file_another_user_planted_unopenable_does_not_deny_the_id(
    shared_lock_dir: Path, env: dict[str, str]
) -> None:
    """daemon may not open nobody's 0600 file; with a pool of one ID it still gets that ID."""
    (first,) = pick_ids(1)
    planted = lock_path(shared_lock_dir, first)
    plant_file(planted, NOBODY, 0o600)
    before = snapshot(planted)
    result_file = shared_lock_dir.parent / "out" / "result.xml"

    result = as_user(
        DAEMON,
        ["run", "--junit-xml", str(result_file), "--", "sh", "-c", PRINT_ID],
        shared_env(env, shared_lock_dir, first),
    )

    assert granted_id(result) == first
    assert snapshot(planted) == before
    own = shared_lock_dir / f"domain-{first}.uid{DAEMON}.lock"
    assert own.stat().st_uid == DAEMON
    assert "<error" not in result_file.read_text(encoding="utf-8")


def test_users_on_either_side_of_a_planted_lock_file_never_hold_one_id_at_once(
    shared_lock_dir: Path, env: dict[str, str], children: Children
) -> None:
    """nobody locks the planted file (its own), daemon its fallback: the port keeps them apart."""
    first, second = pick_ids(2)
    planted = lock_path(shared_lock_dir, first)
    plant_file(planted, NOBODY, 0o600)
    before = snapshot(planted)
    one_id = shared_env(env, shared_lock_dir, first)
    both_ids = shared_env(env, shared_lock_dir, first, second)

    for holder_uid, other_uid in ((DAEMON, NOBODY), (NOBODY, DAEMON)):
        pid_file = shared_lock_dir.parent / f"test-{holder_uid}.pid"
        go = shared_lock_dir.parent / f"go-{holder_uid}"
        holder = children.start(
            [CLI, "run", "--", sys.executable, "-c", WAIT_SCRIPT, str(pid_file), str(go)],
            env=one_id,
            **user_keywords(holder_uid),
        )
        try:
            wait_for(pid_file)
            refused = as_user(other_uid, ["run", "--wait-timeout", "0", "--", "true"], one_id)
            assert refused.returncode == 3, refused.stdout + refused.stderr
            taken = as_user(other_uid, ["run", "--", "sh", "-c", PRINT_ID], both_ids)
            assert granted_id(taken) == second
            assert DomainCoordinator(shared_lock_dir, (first,)).try_reserve(["root"]) is None
        finally:
            go.touch()
        stdout, stderr = holder.communicate(timeout=DEADLINE)
        assert holder.returncode == 0, stdout + stderr
        assert f"Running with ROS_DOMAIN_ID {first}" in stdout
    assert snapshot(planted) == before


def test_planting_the_fallback_lock_file_too_does_not_deny_the_id(
    shared_lock_dir: Path, env: dict[str, str]
) -> None:
    """The fallback name is predictable: nobody can plant it as well as the shared one."""
    (first,) = pick_ids(1)
    shared = lock_path(shared_lock_dir, first)
    fallback = shared_lock_dir / f"domain-{first}.uid{DAEMON}.lock"
    plant_file(shared, NOBODY, 0o600)
    plant_file(fallback, NOBODY, 0o600)
    before = (snapshot(shared), snapshot(fallback))

    result = as_user(
        DAEMON,
        ["run", "--wait-timeout", "0", "--", "sh", "-c", PRINT_ID],
        shared_env(env, shared_lock_dir, first),
    )

    assert granted_id(result) == first
    assert (snapshot(shared), snapshot(fallback)) == before


SYMLINK_TARGETS = ["victim file", "directory", "dangling"]


@pytest.mark.parametrize("target_kind", SYMLINK_TARGETS)
def test_a_symlink_at_a_lock_path_is_never_followed(
    target_kind: str, lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    first, second = pick_ids(2)
    target = tmp_path / "target"
    if target_kind == "victim file":
        plant_file(target, os.getuid(), 0o644, b"precious\n")
    elif target_kind == "directory":
        target.mkdir()
        plant_file(target / "inside", os.getuid(), 0o644, b"precious\n")
    link = lock_path(lock_dir, first)
    link.symlink_to(target)
    before = tree(tmp_path)
    one_id = shared_env(env, lock_dir, first)

    assert granted_id(run_timed(["run", "--", "sh", "-c", PRINT_ID], one_id)) == first

    # Held through the fallback lock, the ID is still kept from everyone else.
    reservation = DomainCoordinator(lock_dir, (first,)).try_reserve(["holder"])
    assert reservation is not None
    try:
        assert reservation.domain_id == first
        refused = run_timed(["run", "--wait-timeout", "0", "--", "true"], one_id)
        assert refused.returncode == 3, refused.stdout + refused.stderr
        both = shared_env(env, lock_dir, first, second)
        assert granted_id(run_timed(["run", "--", "sh", "-c", PRINT_ID], both)) == second
        for args in (["status"], ["status", "--json"]):
            status = run_timed(args, one_id)
            assert status.returncode == 0, status.stderr
            assert "Traceback" not in status.stderr
    finally:
        reservation.release()

    assert tree(tmp_path) == before
    assert os.readlink(link) == str(target)
    if target_kind == "dangling":
        assert not os.path.lexists(target)


SPECIAL_FILES = ["fifo", "directory", "unix socket"]


def plant_special(kind: str, path: Path) -> socket.socket | None:
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    else:
        server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        server.bind(str(path))
        server.listen()
        return server
    return None


@pytest.mark.parametrize("kind", SPECIAL_FILES)
def test_a_fifo_directory_or_socket_at_a_lock_path_neither_hangs_nor_denies(
    kind: str, lock_dir: Path, env: dict[str, str]
) -> None:
    (first,) = pick_ids(1)
    path = lock_path(lock_dir, first)
    server = plant_special(kind, path)
    try:
        before = snapshot(path)
        one_id = shared_env(env, lock_dir, first)
        assert granted_id(run_timed(["run", "--", "sh", "-c", PRINT_ID], one_id)) == first
        status = run_timed(["status"], one_id)
        assert status.returncode == 0, status.stderr
        assert snapshot(path) == before
    finally:
        if server is not None:
            server.close()


def test_status_names_the_holder_of_an_id_held_through_its_fallback_lock(
    lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    """Otherwise ``status`` (and the pool-exhausted message) blames upstream for our own runner."""
    (first,) = pick_ids(1)
    lock_path(lock_dir, first).symlink_to(tmp_path / "nowhere")
    with DomainCoordinator(lock_dir, (first,)).reserve(["my_test"]) as reservation:
        assert reservation.domain_id == first
        (held,) = held_domains(lock_dir, (first,))
    assert held.via == "lock", held
    assert held.holder is not None
    assert held.holder.pid == os.getpid()
    assert held.holder.command == "my_test"


# -- holder records, release stamps, the queue ----------------------------------------------


RUNNER_FILES = ["holder record", "release stamp"]


def runner_file(which: str, lock_dir: Path, domain_id: int, uid: int) -> Path:
    if which == "holder record":
        return record_path(lock_dir, domain_id, uid)
    return lock_dir / f"domain-{domain_id}.uid{uid}.released"


def test_runner_file_names_match_the_coordinator(lock_dir: Path) -> None:
    """The planting tests below aim at these names; they must be the ones the runner uses."""
    uid = os.getuid()
    assert runner_file("release stamp", lock_dir, 7, uid) == release_stamp(lock_dir, 7)
    assert runner_file("holder record", lock_dir, 7, uid) == record_path(lock_dir, 7)
    assert own_lock_path(lock_dir, 7) == lock_dir / f"domain-7.uid{uid}.lock"


@pytest.mark.parametrize("which", RUNNER_FILES)
def test_a_symlink_at_a_record_or_stamp_path_is_never_followed(
    which: str, lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    (first,) = pick_ids(1)
    victim = tmp_path / "victim"
    plant_file(victim, os.getuid(), 0o644, b"precious\n")
    dangling = tmp_path / "nowhere"
    before = snapshot(victim)
    one_id = shared_env(env, lock_dir, first)

    for target in (victim, dangling):
        link = runner_file(which, lock_dir, first, os.getuid())
        link.symlink_to(target)
        assert granted_id(run_timed(["run", "--", "sh", "-c", PRINT_ID], one_id)) == first
        assert snapshot(victim) == before
        assert not os.path.lexists(dangling)
        if os.path.islink(link):
            link.unlink()


@pytest.mark.parametrize("which", RUNNER_FILES)
@pytest.mark.parametrize(
    ("runner", "mode"),
    [
        pytest.param(DAEMON, 0o666, id="daemon-file-0666"),
        pytest.param(0, 0o644, id="root-file-0644"),
    ],
)
def test_a_record_or_stamp_another_user_planted_is_never_written_or_replaced(
    which: str, runner: int, mode: int, shared_lock_dir: Path, env: dict[str, str]
) -> None:
    """nobody plants a file at the runner's own record/stamp name, writable or not."""
    (first,) = pick_ids(1)
    planted = runner_file(which, shared_lock_dir, first, runner)
    plant_file(planted, NOBODY, mode)
    before = snapshot(planted)

    args, environ = ["run", "--", "sh", "-c", PRINT_ID], shared_env(env, shared_lock_dir, first)
    if runner:
        result = run_timed(args, environ, **user_keywords(runner))
    else:
        result = run_timed(args, environ)

    assert granted_id(result) == first
    assert_unchanged(planted, before)


def test_a_queue_symlink_is_never_followed(
    lock_dir: Path, env: dict[str, str], tmp_path: Path
) -> None:
    """Every run looks into the queue; through a link it would unlink a victim's *.ticket files."""
    (first,) = pick_ids(1)
    victim = tmp_path / "victim"
    victim.mkdir()
    plant_file(victim / "precious.ticket", os.getuid(), 0o644)
    (lock_dir / "queue").symlink_to(victim)
    before = tree(victim)

    result = run_timed(["run", "--", "sh", "-c", PRINT_ID], shared_env(env, lock_dir, first))
    assert granted_id(result) == first
    assert tree(victim) == before


def test_a_queue_planted_as_a_file_does_not_deny_a_waiting_runner(
    lock_dir: Path, env: dict[str, str], children: Children
) -> None:
    """A runner that has to wait must still get the ID when it frees up."""
    (first,) = pick_ids(1)
    plant_file(lock_dir / "queue", NOBODY, 0o644)
    before = snapshot(lock_dir / "queue")
    reservation = DomainCoordinator(lock_dir, (first,)).try_reserve(["holder"])
    assert reservation is not None
    try:
        waiter = children.start(
            [CLI, "run", "--wait-timeout", "30", "--", "sh", "-c", PRINT_ID],
            env=shared_env(env, lock_dir, first),
        )
        # It says once that it queues in a folder of its own, naming the planted path.
        note = children.first_line(waiter)
        assert f"shared queue folder {lock_dir / 'queue'} is unusable" in note, note
        assert "waiting for a free ROS_DOMAIN_ID" in children.first_line(waiter)
    finally:
        reservation.release()
    stdout, stderr = waiter.communicate(timeout=DEADLINE)
    assert waiter.returncode == 0, stdout + stderr
    assert f"id={first}" in stdout
    assert snapshot(lock_dir / "queue") == before


def test_a_fifo_at_a_holder_record_path_hangs_neither_status_nor_a_refused_run(
    lock_dir: Path, env: dict[str, str]
) -> None:
    """Reading another user's record must not block: status and 'pool exhausted' read them."""
    (first,) = pick_ids(1)
    other = NOBODY if os.getuid() != NOBODY else DAEMON
    fifo = record_path(lock_dir, first, other)
    os.mkfifo(fifo)
    if os.getuid() == 0:
        os.lchown(fifo, other, other)
    one_id = shared_env(env, lock_dir, first)
    with DomainCoordinator(lock_dir, (first,)).reserve(["holder"]):
        status = run_timed(["status"], one_id)
        assert status.returncode == 0, status.stderr
        assert "holder" in status.stdout
        refused = run_timed(["run", "--wait-timeout", "0", "--", "true"], one_id)
        assert refused.returncode == 3, refused.stdout + refused.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


# -- the lock directory itself --------------------------------------------------------------


LOCK_DIR_KINDS = ["regular file", "symlink to a directory", "symlink to a file", "dangling symlink"]


@pytest.mark.parametrize("kind", LOCK_DIR_KINDS)
def test_a_lock_dir_that_is_not_a_directory_is_refused_with_exit_3(
    kind: str, env: dict[str, str], tmp_path: Path
) -> None:
    """Nothing is created, removed or locked at a symlink's target, even a lock dir's lookalike."""
    (first,) = pick_ids(1)
    target = tmp_path / "target"
    path = tmp_path / "locks"
    if kind == "regular file":
        plant_file(path, os.getuid(), 0o644)
    elif kind == "symlink to a directory":
        (target / "queue").mkdir(parents=True)
        plant_file(target / "queue" / "00000000000000000001-1.ticket", os.getuid(), 0o644)
        plant_file(target / f"domain-{first}.lock", os.getuid(), 0o666, b"")
        path.symlink_to(target)
    elif kind == "symlink to a file":
        plant_file(target, os.getuid(), 0o644)
        path.symlink_to(target)
    else:
        path.symlink_to(target)
    before = tree(tmp_path)
    result_file = tmp_path / "out" / "result.xml"
    marker = tmp_path / "out" / "ran"

    result = run_timed(
        ["run", "--junit-xml", str(result_file), "--", "touch", str(marker)],
        shared_env(env, path, first),
    )

    line = error_line(result)
    assert str(path) in line
    assert LOCK_DIR_ENV in line
    assert "not a directory" in line
    assert str(path) in result_error(result_file)
    assert not marker.exists()
    after = tree(tmp_path)
    after.pop("out")
    after.pop("out/result.xml")
    assert after == before


def test_a_lock_dir_of_another_user_mode_0755_is_refused_for_a_non_root_runner(
    shared_lock_dir: Path, env: dict[str, str]
) -> None:
    (first,) = pick_ids(1)
    os.chown(shared_lock_dir, NOBODY, NOBODY)
    os.chmod(shared_lock_dir, 0o755)
    result_file = shared_lock_dir.parent / "out" / "result.xml"

    result = as_user(
        DAEMON,
        ["run", "--junit-xml", str(result_file), "--", "true"],
        shared_env(env, shared_lock_dir, first),
    )

    line = error_line(result)
    assert str(shared_lock_dir) in line
    assert f"chmod 1777 {shared_lock_dir}" in line
    assert "read-only" not in line
    assert LOCK_DIR_ENV in line
    assert str(shared_lock_dir) in result_error(result_file)
    assert list(shared_lock_dir.iterdir()) == []


# -- read-only and full file systems (private mount namespaces) -----------------------------


@pytest.fixture
def mount_point(tmp_path: Path) -> Iterator[Path]:
    """An empty directory; mounts on it live in a namespace that dies with the run."""
    capabilities.require(capabilities.MOUNT_NAMESPACE)
    unshare = shutil.which("unshare")
    assert unshare is not None
    path = tmp_path / "mnt"
    path.mkdir()
    probe = subprocess.run(
        [
            unshare,
            "--mount",
            "--propagation",
            "private",
            "mount",
            "-t",
            "tmpfs",
            "tmpfs",
            str(path),
        ],
        check=False,
        capture_output=True,
        text=True,
        timeout=DEADLINE,
    )
    assert probe.returncode == 0, probe.stderr
    yield path
    assert not os.path.ismount(path), "a mount leaked out of its namespace"


def in_namespace(
    setup: str, args: list[str], env: dict[str, str]
) -> subprocess.CompletedProcess[str]:
    """``ros-isolated-test ARGS`` after the shell ``setup`` in a private mount namespace."""
    script = f'set -e; {setup}; echo setup-done >&2; exec "$@"'
    result = subprocess.run(
        ["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh", CLI, *args],
        check=False,
        env=env,
        capture_output=True,
        text=True,
        timeout=HANG,
    )
    assert "setup-done" in result.stderr, result.stderr
    result.stderr = result.stderr.replace("setup-done\n", "", 1)
    return result


READ_ONLY_CASES = [
    pytest.param(True, True, id="read-only-lock-dir-exists"),
    pytest.param(True, False, id="read-only-lock-dir-missing"),
    pytest.param(False, True, id="control-writable-lock-dir-exists"),
    pytest.param(False, False, id="control-writable-lock-dir-missing"),
]


@pytest.mark.parametrize(("read_only", "lock_dir_exists"), READ_ONLY_CASES)
def test_a_read_only_lock_dir_names_the_read_only_file_system_not_chmod(
    read_only: bool,
    lock_dir_exists: bool,
    mount_point: Path,
    env: dict[str, str],
    tmp_path: Path,
) -> None:
    """Root bypasses permissions, not a read-only mount, and no chmod can fix one.

    The directory is already mode 1777, so advice to chmod it is wrong; the only fix is
    another directory. The control is the same bind mount left writable: the run works.
    """
    (first,) = pick_ids(1)
    os.chmod(mount_point, 0o1777)
    lock_dir = mount_point if lock_dir_exists else mount_point / "locks"
    result_file = tmp_path / "result.xml"
    marker = tmp_path / "ran"
    where = shlex.quote(str(mount_point))
    setup = f"mount --bind {where} {where}"
    if read_only:
        setup += f"; mount -o remount,bind,ro {where}"

    result = in_namespace(
        setup,
        ["run", "--junit-xml", str(result_file), "--", "sh", "-c", f"{PRINT_ID}; touch {marker}"],
        shared_env(env, lock_dir, first),
    )

    if not read_only:
        assert granted_id(result) == first
        assert marker.exists()
        return
    line = error_line(result)
    assert str(lock_dir) in line
    assert "read-only file system" in line
    assert "chmod" not in line
    assert "mode 1777" not in line
    assert LOCK_DIR_ENV in line
    assert str(lock_dir) in result_error(result_file)
    assert not marker.exists()
    assert list(mount_point.iterdir()) == []


#: A 16 KiB tmpfs with 8 inodes: fill the data, then every inode.
FILL = (
    "mount -t tmpfs -o size=16k,nr_inodes=8,mode=1777 tmpfs {dir}; "
    "dd if=/dev/zero of={dir}/fill bs=4k 2>/dev/null || true; "
    "i=0; while touch {dir}/f$i 2>/dev/null; do i=$((i+1)); done"
)


@pytest.mark.parametrize(
    "lock_dir_exists", [True, False], ids=["lock-dir-exists", "lock-dir-missing"]
)
def test_a_full_disk_is_refused_with_exit_3_naming_the_path_and_the_fix(
    lock_dir_exists: bool, mount_point: Path, env: dict[str, str], tmp_path: Path
) -> None:
    (first,) = pick_ids(1)
    where = shlex.quote(str(mount_point))
    lock_dir = mount_point if lock_dir_exists else mount_point / "locks"
    result_file = tmp_path / "result.xml"
    marker = tmp_path / "ran"

    result = in_namespace(
        FILL.format(dir=where),
        ["run", "--junit-xml", str(result_file), "--", "touch", str(marker)],
        shared_env(env, lock_dir, first),
    )

    line = error_line(result)
    named = lock_path(lock_dir, first) if lock_dir_exists else lock_dir
    assert str(named) in line
    assert "No space left on device" in line
    assert LOCK_DIR_ENV in line
    if lock_dir_exists:
        assert "free space" in line
    assert str(named) in result_error(result_file)
    assert not marker.exists()


def test_a_disk_with_no_data_space_left_still_takes_lock_files(
    mount_point: Path, env: dict[str, str]
) -> None:
    """Lock files are empty: only the holder record needs data, and the run does without it."""
    (first,) = pick_ids(1)
    where = shlex.quote(str(mount_point))
    setup = (
        f"mount -t tmpfs -o size=16k,mode=1777 tmpfs {where}; "
        f"dd if=/dev/zero of={where}/fill bs=4k 2>/dev/null || true"
    )
    result = in_namespace(
        setup, ["run", "--", "sh", "-c", PRINT_ID], shared_env(env, mount_point, first)
    )
    assert granted_id(result) == first
