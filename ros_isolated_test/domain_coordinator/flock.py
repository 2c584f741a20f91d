"""The coordinator's lock primitive: filelock's native lock, a whole-file ``flock``.

Every reservation, ticket and status probe takes an exclusive ``flock`` of the whole
file, which is what ``filelock.FileLock`` takes on Unix (every version, 3.13.1 as
Ubuntu 24.04 ships it included): our holders and any filelock user contend on the same
files. The runner never imports filelock for it. The import alone costs about 45 ms per
process, more than twice everything else the runner does for a test, and the call that
waited for us (``lock_descriptor``, filelock 3.30+) retries a non-blocking ``flock``
every 50 ms where the kernel can wake the waiter itself.
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
    """Block in the kernel until the exclusive lock on ``fd`` is held: one call, no polling.

    Raises OSError when ``fd`` cannot be locked at all. A signal whose handler returns
    resumes the wait (PEP 475); one whose handler raises ends it with that exception.
    """
    fcntl.flock(fd, fcntl.LOCK_EX)
