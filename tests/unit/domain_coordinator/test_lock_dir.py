"""``lock_dir``: the one lock directory every runner, user and container shares, and its files.

Where it is: ``ROS_ISOLATED_TEST_LOCK_DIR``, else one fixed path under /tmp that is the
same for every user (never ``$TMPDIR``, ``$HOME`` or ``$USER``), so all runners on a
machine see one set of locks. A missing one is created mode 1777 at once, whatever the
umask.

One opener for every lock file: the ID's lock files and the resources' mutex alike. A
lock file lives in a directory every user may write to: one it creates is made openable
by every user whatever the umask, one that exists (another user's, or ours) is opened
read-only and left as it is, and anything planted (a symlink, a FIFO, a directory) is
refused without being followed, so each caller falls back to a lock file of its own
user. Files read back from there are read the same way: never through a link, never
blocking on a FIFO. (A lock directory that cannot be used: ``test_lock_dir_unusable``.)
"""

from __future__ import annotations

import os
import pwd
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import run_cli
from helpers.coordinator import PRINT_ID, ids_seen
from helpers.domains import free_ids

from ros_isolated_test.domain_coordinator import (
    LOCK_DIR_ENV,
    DomainCoordinator,
    lock_dir_from_env,
    resource_holds,
)
from ros_isolated_test.domain_coordinator.lock_dir import (
    LOCK_FILE_MODE,
    UnusableLockFile,
    open_lock_file,
    owned_file,
    read_small_file,
)
from ros_isolated_test.domain_coordinator.lock_files import lock_path

NOBODY = 65534


def mode(path: Path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


@pytest.fixture
def strict_umask() -> Iterator[None]:
    """The umask of a careful user: new files are theirs alone unless chmodded."""
    old = os.umask(0o077)
    try:
        yield
    finally:
        os.umask(old)


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
    result = run_cli(["run", "--", "sh", "-c", PRINT_ID], env)
    assert result.returncode == 0, result.stdout + result.stderr
    (seen,) = ids_seen(result.stdout)
    assert lock_path(elsewhere, seen).is_file()
    assert not list(lock_dir.iterdir())


# -- a missing lock directory is created shared --------------------------------------------


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


# -- the one opener of lock files ----------------------------------------------------------


@pytest.mark.usefixtures("strict_umask")
def test_a_new_lock_file_is_openable_by_every_user_whatever_the_umask(lock_dir: Path) -> None:
    """The reservation's lock file and the resources' mutex alike: one opener."""
    control = lock_dir / "plain"
    os.close(os.open(control, os.O_RDONLY | os.O_CREAT, LOCK_FILE_MODE))
    assert mode(control) == 0o600  # the control: the umask cuts what open() asks for
    (domain_id,) = free_ids(1)
    reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["created"])
    assert reservation is not None
    reservation.release()
    with resource_holds.mutex(lock_dir) as held:
        assert held
    created = [lock_path(lock_dir, domain_id), lock_dir / resource_holds.MUTEX]
    assert [mode(path) for path in created] == [LOCK_FILE_MODE] * 2 == [0o666] * 2


def test_an_existing_lock_file_is_never_changed_ours_included(lock_dir: Path) -> None:
    """Whoever made it narrower meant it: the ID's lock file and the mutex are left as found.

    Other users then fall back to lock files of their own, as for a planted file.
    """
    (domain_id,) = free_ids(1)
    found = [lock_path(lock_dir, domain_id), lock_dir / resource_holds.MUTEX]
    for path in found:
        path.touch()
        os.chmod(path, 0o600)
    reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["as found"])
    assert reservation is not None
    reservation.release()
    with resource_holds.mutex(lock_dir) as held:
        assert held
    assert [mode(path) for path in found] == [0o600, 0o600]


@capabilities.ROOT
def test_a_lock_file_of_another_user_is_used_as_it_is(tmp_path: Path) -> None:
    path = tmp_path / "domain-7.lock"
    path.touch()
    os.chown(path, NOBODY, NOBODY)
    os.chmod(path, 0o644)
    os.close(open_lock_file(path))
    info = os.lstat(path)
    assert (info.st_uid, stat.S_IMODE(info.st_mode)) == (NOBODY, 0o644)


def _plant(kind: str, path: Path, victim: Path) -> None:
    """A symlink to ``victim``, a FIFO or a directory at ``path``."""
    if kind == "symlink":
        path.symlink_to(victim)
    elif kind == "fifo":
        os.mkfifo(path)  # opening it for reading without O_NONBLOCK would hang
    else:
        path.mkdir()


@pytest.mark.parametrize("kind", ["symlink", "fifo", "directory"])
def test_anything_planted_is_refused_and_never_followed(kind: str, tmp_path: Path) -> None:
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious\n")
    os.chmod(victim, 0o600)
    path = tmp_path / "domain-7.lock"
    _plant(kind, path, victim)
    with pytest.raises(UnusableLockFile, match=r"domain-7\.lock"):
        open_lock_file(path)
    assert (victim.read_bytes(), mode(victim)) == (b"precious\n", 0o600)
    os.close(open_lock_file(tmp_path / "domain-8.lock"))  # the control: a free name opens


# -- reading and owning files in the shared directory ---------------------------------------


@pytest.mark.parametrize("kind", ["symlink", "fifo", "directory"])
def test_a_small_file_is_read_only_when_it_is_a_regular_file(kind: str, tmp_path: Path) -> None:
    """A record read back is read through no link, and a FIFO planted there hangs nobody."""
    victim = tmp_path / "victim"
    victim.write_text("secret\n")
    path = tmp_path / "domain-7.uid0.holder.json"
    _plant(kind, path, victim)
    with pytest.raises(OSError):
        read_small_file(path)
    # The control: a regular file is read, up to the limit asked.
    record = tmp_path / "record"
    record.write_text('{"pid": 1}')
    assert read_small_file(record) == '{"pid": 1}'
    assert read_small_file(record, limit=4) == '{"pi'


@pytest.mark.parametrize("kind", ["symlink", "fifo", "directory", "missing"])
def test_an_owned_file_is_a_regular_file_of_ours_and_nothing_else(
    kind: str, tmp_path: Path
) -> None:
    ours = tmp_path / "ours"
    ours.write_text("")
    assert owned_file(ours)  # the control: our own regular file
    path = tmp_path / "entry"
    if kind != "missing":
        _plant(kind, path, ours)
    assert not owned_file(path)


@capabilities.ROOT
def test_a_file_of_another_user_is_not_owned(tmp_path: Path) -> None:
    path = tmp_path / "theirs"
    path.write_text("")
    assert owned_file(path)  # the control: the same file, ours
    os.chown(path, NOBODY, NOBODY)
    assert not owned_file(path)
