"""Block records: survivors of an ID's last test keep the ID from every runner while they live.

A runner that could not end its test's whole tree records the survivors before it
releases the ID (:meth:`Reservation.block_for`); each reservation then looks for such
records with one lstat of a marker, and only reads them when the marker is there.
Records live in the shared lock directory, so they are per user, never followed through
a link, and judged only in the boot and PID namespace that wrote them.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable
from pathlib import Path

from ros_isolated_test.atomic_file import write_atomically
from ros_isolated_test.domain_coordinator import records
from ros_isolated_test.domain_coordinator.lock_dir import owned_file, read_small_file
from ros_isolated_test.process import proc


def block_marker(lock_dir: Path, domain_id: int) -> Path:
    """A file whose presence says "look for block records": one lstat per candidate ID.

    Created by whichever user blocks the ID first; records are per user (see
    :func:`write_block`), since no user writes a file another user owns.
    """
    return lock_dir / f"domain-{domain_id}.blocked"


#: First line of a block record: what the file is, and its format's version.
_BLOCK_HEADER = "ros-isolated-test survivors 1"


def write_block(lock_dir: Path, domain_id: int, processes: Iterable[proc.Stat]) -> Path:
    """Record survivors of the ID's last test, so no runner takes the ID while they live.

    Each process is named by PID and start time (a recycled PID is another process),
    with this boot's ID and our PID namespace (another boot's or namespace's PIDs name
    other processes). The marker comes first: a record no one looks for blocks nothing.
    Raises OSError when the block cannot be recorded.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    with contextlib.suppress(FileExistsError):  # whoever made it, it says the same
        os.close(os.open(block_marker(lock_dir, domain_id), flags, 0o644))
    lines = [_BLOCK_HEADER, f"boot {proc.boot_id()}", f"pidns {proc.pid_namespace()}"]
    lines += [f"{process.pid} {process.start}" for process in processes]
    # A name of our own, never guessed by someone planting files: nothing is overwritten.
    token = f"{os.getpid()}-{os.urandom(4).hex()}"
    path = lock_dir / f"domain-{domain_id}.uid{os.getuid()}.{token}.blocked"
    write_atomically(path, ("\n".join(lines) + "\n").encode("utf-8"))
    return path


def blocking_survivors(lock_dir: Path, domain_id: int, clean: bool = False) -> list[proc.Stat]:
    """The live processes that block the ID (named by a block record), usually none.

    One lstat when the ID is not blocked. Records whose processes are all gone count for
    nothing; with ``clean`` (the caller holds the ID, so no block is being written) our
    own such records are removed, then the marker when it is ours and no record is left.
    """
    marker = block_marker(lock_dir, domain_id)
    try:
        os.lstat(marker)
    except OSError:
        return []
    alive: list[proc.Stat] = []
    records_left = False
    for path in _block_records(lock_dir, domain_id):
        named = _read_block(path)
        if named is None:  # unreadable, or another namespace's: not ours to judge
            records_left = True
            continue
        found = [stat for pid, start in named if (stat := proc.living(pid, start)) is not None]
        alive += found
        if found or not clean or not owned_file(path):
            records_left = True
        else:
            records.remove_record(path)
    if clean and not records_left and owned_file(marker):
        with contextlib.suppress(OSError):
            marker.unlink()
    return alive


def _block_records(lock_dir: Path, domain_id: int) -> list[Path]:
    prefix = f"domain-{domain_id}.uid"
    paths: list[Path] = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(lock_dir):
            if entry.name.startswith(prefix) and entry.name.endswith(".blocked"):
                paths.append(Path(entry.path))
    return paths


def _read_block(path: Path) -> list[tuple[int, int]] | None:
    """The (pid, start) pairs a record names; None when it cannot be judged here.

    A record of another boot names nobody (all its processes are gone).
    """
    try:
        lines = read_small_file(path).splitlines()
    except (OSError, ValueError):
        return None
    if len(lines) < 3 or lines[0] != _BLOCK_HEADER:
        return None
    if lines[1] != f"boot {proc.boot_id()}":
        return []
    if lines[2] != f"pidns {proc.pid_namespace()}":
        return None
    named: list[tuple[int, int]] = []
    for line in lines[3:]:
        with contextlib.suppress(ValueError):
            pid, start = line.split()
            named.append((int(pid), int(start)))
    return named
