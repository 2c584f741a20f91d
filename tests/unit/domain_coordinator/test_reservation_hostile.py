"""A lock directory shared by all users is hostile ground: planted lock files and records.

Anyone may create entries in a mode-1777 directory, at any name a runner uses: an ID's
lock file (another user's unopenable file, a symlink, a FIFO, a directory, a socket),
the fallback lock file of a user, a holder record or a release stamp. Whatever is
planted there, the runner never follows a symlink, never writes or replaces a file it
does not own, still gets its ID (through a lock file of its own; the port keeps two
holders of one ID apart), and otherwise fails with exit 3, one line naming the path and
the fix, and a result file saying the same. ``status`` still names the runner holding
an ID through its fallback lock, and never hangs on a FIFO planted at a record's path.

The root-owned planted entries sit in pytest's private (non-sticky) directories on
purpose: fs.protected_symlinks/protected_regular only guard sticky world-writable
directories, so there a runner that followed a link would really reach its target.
(A planted queue: ``test_queue``; a planted lock directory: ``test_lock_dir_unusable``.)
"""

from __future__ import annotations

import os
import socket
import stat
import sys
from pathlib import Path

import pytest
from helpers.commands import CLI, run_cli
from helpers.coordinator import PRINT_ID, error_lines, without_domain_id
from helpers.domains import free_ids
from helpers.hostile_lock_dir import (
    DAEMON,
    NOBODY,
    as_user,
    assert_unchanged,
    granted_id,
    make_shared_lock_dir,
    pick_ids,
    plant_file,
    run_timed,
    shared_env,
    snapshot,
    tree,
)
from helpers.processes import DEADLINE, WAIT_SCRIPT, Children, user_keywords, wait_for
from helpers.results import result_error

from ros_isolated_test.domain_coordinator import (
    LOCK_DIR_ENV,
    POOL_ENV,
    DomainCoordinator,
    domain_uses,
)
from ros_isolated_test.domain_coordinator.lock_files import lock_path, own_lock_path
from ros_isolated_test.domain_coordinator.port_guard import port_is_taken
from ros_isolated_test.domain_coordinator.records import record_path
from ros_isolated_test.domain_coordinator.reservation import release_stamp

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


def test_an_unwritable_lock_file_of_another_user_does_not_lock_everyone_out(
    traversable_dir: Path,
) -> None:
    """Only its owner can remove it from the sticky dir: failing on it stops every run.

    The rest of the pool is free, and a flock needs no write access to the file.
    """
    nobody, daemon = 65534, 1
    first, second = free_ids(2)
    lock_dir = make_shared_lock_dir(traversable_dir)
    stray = lock_path(lock_dir, first)
    stray.touch(mode=0o600)
    os.chown(stray, nobody, -1)
    os.chmod(stray, 0o600)
    env = {
        **without_domain_id(),
        LOCK_DIR_ENV: str(lock_dir),
        POOL_ENV: f"{first},{second}",
    }
    result = run_timed(
        ["run", "--", "sh", "-c", PRINT_ID], env, timeout=120, **user_keywords(daemon)
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "id=" in result.stdout


# -- something else planted at a lock path --------------------------------------------------


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
        lines = error_lines(result.stderr)
        assert len(lines) == 1, result.stderr
        assert str(path) in lines[0]
        assert str(path) in result_error(result_file)

    status = run_cli(["status"], env)
    assert "Traceback" not in status.stderr, status.stderr
    assert status.returncode == 0, status.stderr


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
        (held,) = domain_uses(lock_dir, (first,))
    assert held.via == "lock", held
    assert held.holder is not None
    assert held.holder.pid == os.getpid()
    assert held.holder.command == "my_test"


# -- holder records and release stamps -------------------------------------------------------


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
