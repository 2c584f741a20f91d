"""Which files hold an ID's reservation, and whether any of them is held right now.

Its own module so that both the reservation (which takes the locks) and ``status``
(which looks at them, and which the reservation asks who holds the pool) can use the
names and the probe without importing each other.
"""

from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path

from ros_isolated_test.domain_coordinator.flock import try_lock


def lock_path(lock_dir: Path, domain_id: int) -> Path:
    """The file whose flock is the reservation of ``domain_id``."""
    return lock_dir / f"domain-{domain_id}.lock"


def own_lock_path(lock_dir: Path, domain_id: int) -> Path:
    """The lock file of the current user for the ID, used when the shared one was planted."""
    return lock_dir / f"domain-{domain_id}.uid{os.getuid()}.lock"


def lock_files(lock_dir: Path, domain_id: int) -> list[Path]:
    """The shared lock file of the ID and every user's own one."""
    paths = [lock_path(lock_dir, domain_id)]
    with contextlib.suppress(OSError):
        prefix = f"domain-{domain_id}.uid"
        for entry in os.scandir(lock_dir):
            if entry.name.startswith(prefix) and entry.name.endswith(".lock"):
                paths.append(Path(entry.path))
    return paths


def probe_lock(lock_dir: Path, domain_id: int) -> bool:
    """Whether any lock file of the ID (shared, or a user's own) is held right now.

    A lock file flock cannot lock at all counts as held: better an ID passed over than
    one handed out twice.
    """
    for path in lock_files(lock_dir, domain_id):
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
        except OSError:
            continue
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                continue
            try:
                free = try_lock(fd)
            except OSError:
                free = False
            if not free:
                return True
        finally:
            os.close(fd)  # also lets go of the lock the probe took
    return False
