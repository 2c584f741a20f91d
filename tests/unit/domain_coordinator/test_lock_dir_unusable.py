"""A lock directory that cannot be used is refused clearly, and nothing is done through it.

``ensure_lock_dir`` and the lock-file opener refuse what is not a directory they may use:
a file or a symlink where the directory should be (nothing is created, removed or locked
at a symlink's target, even a lock directory's lookalike), another user's directory
mode 0755, a missing parent, a read-only mount (where no chmod helps, so none is advised)
and a full disk. Each refusal is exit 3, one line naming the path and the fix, and a
result file saying the same. Each has its control: the same mount left writable works,
and a disk with no data space left still takes the (empty) lock files.

The read-only and full file systems are real mounts, in private mount namespaces.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, run_cli
from helpers.coordinator import PRINT_ID, error_lines
from helpers.domains import free_ids
from helpers.hostile_lock_dir import (
    DAEMON,
    HANG,
    NOBODY,
    as_user,
    error_line,
    granted_id,
    pick_ids,
    plant_file,
    run_timed,
    shared_env,
    tree,
)
from helpers.processes import DEADLINE
from helpers.results import result_error

from ros_isolated_test.domain_coordinator import LOCK_DIR_ENV, DomainCoordinator, LockDirError
from ros_isolated_test.domain_coordinator.lock_files import lock_path


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
    lines = error_lines(result.stderr)
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
