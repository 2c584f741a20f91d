"""``lock_files``: which files hold an ID's reservation, and whether one is held right now.

An ID is held through its shared lock file or, where that was planted, through a user's
own one (``domain-N.uid<UID>.lock``): ``status`` and the waiting messages ask
``probe_lock`` about all of them. The probe is checked against a real flock held by
another process, with its controls: the same file free, and free again once let go (the
probe's own instant lock goes with it). Anything planted at a lock path that is not a
regular file (a FIFO, a link) is passed over without blocking or being followed.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
from pathlib import Path

from helpers.coordinator import FLOCK_SCRIPT
from helpers.processes import Children

from ros_isolated_test.domain_coordinator.lock_files import (
    lock_files,
    lock_path,
    own_lock_path,
    probe_lock,
)


def _held_by_a_child(children: Children, path: Path) -> subprocess.Popen[str]:
    """A child process holding an exclusive flock of ``path`` until it is finished."""
    holder = children.python(FLOCK_SCRIPT, path)
    assert children.first_line(holder) == "locked"
    return holder


def test_an_ids_lock_files_are_the_shared_one_and_each_users_own(lock_dir: Path) -> None:
    uid = os.getuid()
    assert lock_path(lock_dir, 7) == lock_dir / "domain-7.lock"
    assert own_lock_path(lock_dir, 7) == lock_dir / f"domain-7.uid{uid}.lock"
    # The shared one is named even before it exists: the first runner creates it.
    assert lock_files(lock_dir, 7) == [lock_dir / "domain-7.lock"]
    others = [lock_dir / f"domain-7.uid{user}.lock" for user in (uid, 4242)]
    unrelated = ["domain-70.uid4242.lock", "domain-7.uid4242.released", "domain-17.lock"]
    for path in [*others, *(lock_dir / name for name in unrelated)]:
        path.touch()
    found = lock_files(lock_dir, 7)
    assert found[0] == lock_dir / "domain-7.lock"
    assert sorted(found[1:]) == sorted(others)


def test_the_probe_sees_a_flock_another_process_holds(lock_dir: Path, children: Children) -> None:
    path = lock_path(lock_dir, 7)
    assert not probe_lock(lock_dir, 7)  # the control: no file yet, nothing held
    holder = _held_by_a_child(children, path)
    assert probe_lock(lock_dir, 7)
    assert not probe_lock(lock_dir, 8)  # another ID's lock says nothing about this one
    children.finish(holder)
    assert not probe_lock(lock_dir, 7)
    # The probe let go of the instant lock it took: anyone can take the ID now.
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(fd)


def test_the_probe_sees_an_id_held_through_a_users_own_lock_file(
    lock_dir: Path, children: Children
) -> None:
    """The shared lock file is free (or planted): the holder locked its user's own one."""
    lock_path(lock_dir, 7).touch()
    own = lock_dir / "domain-7.uid4242.lock"
    holder = _held_by_a_child(children, own)
    assert probe_lock(lock_dir, 7)
    children.finish(holder)
    assert not probe_lock(lock_dir, 7)  # the control: the same files, nobody holding


def test_the_probe_passes_over_a_fifo_and_never_follows_a_link(
    lock_dir: Path, tmp_path: Path, children: Children
) -> None:
    """A FIFO would block an open without O_NONBLOCK; a link would lead to another's lock."""
    target = tmp_path / "held-elsewhere"
    holder = _held_by_a_child(children, target)
    os.mkfifo(lock_path(lock_dir, 7))
    own_lock_path(lock_dir, 7).symlink_to(target)
    assert not probe_lock(lock_dir, 7)
    # The control: the held file itself, at an ID's lock path, is seen held.
    os.link(target, lock_path(lock_dir, 8))
    assert probe_lock(lock_dir, 8)
    children.finish(holder)
