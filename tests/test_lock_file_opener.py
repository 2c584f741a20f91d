"""One opener for every lock file: the ID's lock files and the resources' mutex alike.

A lock file lives in a directory every user may write to: one it creates is made
openable by every user whatever the umask, one that exists (another user's, or ours) is
opened read-only and left as it is, and anything planted (a symlink, a FIFO, a
directory) is refused without being followed, so each caller falls back to a lock file
of its own user.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.domains import free_ids

from ros_isolated_test.domain_coordinator import holdings
from ros_isolated_test.domain_coordinator.lock_dir import (
    LOCK_FILE_MODE,
    UnusableLockFile,
    open_lock_file,
)
from ros_isolated_test.domain_coordinator.lock_files import lock_path
from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator

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
    with holdings.mutex(lock_dir) as held:
        assert held
    created = [lock_path(lock_dir, domain_id), lock_dir / holdings.MUTEX]
    assert [mode(path) for path in created] == [LOCK_FILE_MODE] * 2 == [0o666] * 2


def test_an_existing_lock_file_is_never_changed_ours_included(lock_dir: Path) -> None:
    """Whoever made it narrower meant it: the ID's lock file and the mutex are left as found.

    Other users then fall back to lock files of their own, as for a planted file.
    """
    (domain_id,) = free_ids(1)
    found = [lock_path(lock_dir, domain_id), lock_dir / holdings.MUTEX]
    for path in found:
        path.touch()
        os.chmod(path, 0o600)
    reservation = DomainCoordinator(lock_dir, (domain_id,)).try_reserve(["as found"])
    assert reservation is not None
    reservation.release()
    with holdings.mutex(lock_dir) as held:
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


@pytest.mark.parametrize("kind", ["symlink", "fifo", "directory"])
def test_anything_planted_is_refused_and_never_followed(kind: str, tmp_path: Path) -> None:
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious\n")
    os.chmod(victim, 0o600)
    path = tmp_path / "domain-7.lock"
    if kind == "symlink":
        path.symlink_to(victim)
    elif kind == "fifo":
        os.mkfifo(path)  # opening it for reading without O_NONBLOCK would hang
    else:
        path.mkdir()
    with pytest.raises(UnusableLockFile, match=r"domain-7\.lock"):
        open_lock_file(path)
    assert (victim.read_bytes(), mode(victim)) == (b"precious\n", 0o600)
    os.close(open_lock_file(tmp_path / "domain-8.lock"))  # the control: a free name opens


def test_a_planted_mutex_leaves_the_resources_to_this_users_own_lock_file(
    lock_dir: Path,
) -> None:
    os.mkfifo(lock_dir / holdings.MUTEX)
    own = lock_dir / f"resources.uid{os.getuid()}.lock"
    assert not own.exists()
    with holdings.mutex(lock_dir) as held:
        assert held
        assert stat.S_ISREG(os.lstat(own).st_mode)
    assert stat.S_ISFIFO(os.lstat(lock_dir / holdings.MUTEX).st_mode)
