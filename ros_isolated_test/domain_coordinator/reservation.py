"""Reserving a domain ID: one flock'ed file per ID, plus upstream's TCP port.

The kernel drops a flock when the last descriptor of its open file closes, so an ID
comes free however its holder dies (exit, crash, SIGKILL): no stale-lock cleanup, no
timeouts, no daemon. The descriptor is close-on-exec: the test does not inherit it.
"""

from __future__ import annotations

import contextlib
import os
import socket
import stat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from filelock import lock_descriptor

from ros_isolated_test.domain_coordinator import holder, port_guard
from ros_isolated_test.domain_coordinator.lock_dir import ensure_lock_dir, lock_dir_from_env
from ros_isolated_test.domain_coordinator.pool import pool_from_env

#: Lock files are shared by all users: each must be able to open and flock them.
LOCK_FILE_MODE = 0o666


class PoolExhaustedError(RuntimeError):
    """Every ID in the pool is held; the message says by whom and what to do."""


def lock_path(lock_dir: Path, domain_id: int) -> Path:
    """The file whose flock is the reservation of ``domain_id``."""
    return lock_dir / f"domain-{domain_id}.lock"


@dataclass
class Reservation:
    """A held domain ID. Release it with :meth:`release` (or leave the ``with`` block)."""

    domain_id: int
    lock_fd: int
    port: socket.socket
    record: Path
    released: bool = field(default=False, init=False)

    def release(self) -> None:
        """Give the ID back: record first, so ``status`` never names a holder that left."""
        if self.released:
            return
        self.released = True
        holder.remove_record(self.record)
        self.port.close()
        os.close(self.lock_fd)


def _open_lock_file(path: Path) -> int | None:
    """A read-only descriptor of the ID's lock file, created shared if missing.

    Read-only is enough for flock, so a lock file another user created can be used
    whatever its mode lets us write. Never follows a symlink; anything but a regular
    file at the path (planted by someone, in a world-writable directory) means None.
    """
    flags = os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK
    try:
        fd = os.open(path, flags | os.O_CREAT | os.O_EXCL, LOCK_FILE_MODE)
    except FileExistsError:
        try:
            fd = os.open(path, flags)
        except OSError:
            return None
    except OSError:
        return None
    else:
        # The umask cut the mode; every user must be able to open the file.
        with contextlib.suppress(OSError):
            os.fchmod(fd, LOCK_FILE_MODE)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        return None
    return fd


def try_lock(lock_dir: Path, domain_id: int) -> int | None:
    """One non-blocking attempt at the ID's lock: the held descriptor, or None.

    None also when the lock path is unusable (a directory or symlink planted there):
    such an ID is skipped rather than trusted.
    """
    fd = _open_lock_file(lock_path(lock_dir, domain_id))
    if fd is None:
        return None
    try:
        if lock_descriptor(fd, blocking=False):
            return fd
    except OSError:
        pass
    os.close(fd)
    return None


class DomainCoordinator:
    """Hands out domain IDs from a pool, machine-wide, through a shared lock directory."""

    def __init__(self, lock_dir: Path | None = None, pool: Sequence[int] | None = None) -> None:
        self.lock_dir = lock_dir if lock_dir is not None else lock_dir_from_env()
        self.pool = tuple(pool) if pool is not None else pool_from_env()

    def try_reserve(self, command: Sequence[str]) -> Reservation | None:
        """The first free ID of the pool, held; None when all are taken.

        An ID counts as free only when both its lock and its TCP port can be taken, so
        runners of upstream's ``domain_coordinator`` on this machine are respected.
        """
        ensure_lock_dir(self.lock_dir)
        for domain_id in self.pool:
            lock_fd = try_lock(self.lock_dir, domain_id)
            if lock_fd is None:
                continue
            port = port_guard.claim_port(domain_id)
            if port is None:
                os.close(lock_fd)
                continue
            try:
                record = holder.write_record(self.lock_dir, domain_id, command)
            except BaseException:
                port.close()
                os.close(lock_fd)
                raise
            return Reservation(domain_id, lock_fd, port, record)
        return None

    @contextlib.contextmanager
    def reserve(self, command: Sequence[str]) -> Iterator[Reservation]:
        """Hold a free ID for the ``with`` block; :class:`PoolExhaustedError` if there is none."""
        reservation = self.try_reserve(command)
        if reservation is None:
            raise PoolExhaustedError(
                f"all {len(self.pool)} domain IDs of the pool are held "
                f"(see `ros-isolated-test status`); run fewer tests at once (ctest -j), "
                "or widen the pool with ROS_ISOLATED_TEST_DOMAINS, e.g. '1-101,215-232'"
            )
        try:
            yield reservation
        finally:
            reservation.release()
