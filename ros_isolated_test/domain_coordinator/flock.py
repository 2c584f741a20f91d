"""The coordinator's lock primitive: filelock's native lock, a whole-file ``flock``.

Every reservation, ticket and status probe takes the same exclusive ``flock`` that
``filelock`` takes (``FileLock`` on Unix, and ``lock_descriptor`` over a descriptor),
so our holders and any filelock user contend on the same files. A runner's one
non-blocking attempt per ID calls ``fcntl.flock`` directly: importing filelock costs
about 45 ms per process here, more than twice everything else the runner does for a
test. Where a runner waits anyway (its place in the queue), filelock itself does it.
"""

from __future__ import annotations

import errno
import fcntl

#: What flock says when another open file holds the lock.
_BUSY = frozenset({errno.EAGAIN, errno.EWOULDBLOCK})


def try_lock(fd: int) -> bool:
    """One non-blocking attempt at the exclusive lock on ``fd``: False if someone holds it.

    Raises OSError for anything but contention (a descriptor flock cannot lock).
    """
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as error:
        if error.errno in _BUSY:
            return False
        raise
    return True


def wait_lock(fd: int) -> None:
    """Block until the exclusive lock on ``fd`` is held (filelock's ``lock_descriptor``)."""
    from filelock import lock_descriptor

    lock_descriptor(fd, blocking=True)
