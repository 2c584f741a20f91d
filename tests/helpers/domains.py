"""Picking domain IDs for a test: ones nobody on this machine uses right now.

Ports 32768+ID and the processes' environments are machine-wide, and other runners hold
IDs in the default lock directory, so a test never assumes an ID is free: it takes IDs
whose lock, port, environment and DDS ports are all unused now, from 215-232 where it can (outside
the default pool and upstream's 1-100, where other runs on this machine rarely are).

Other sessions of this suite on the machine (xdist's workers, a second checkout's run)
pick from the same IDs, and an ID free when checked may be theirs a moment later, before
either test reserved it: each ID picked is claimed too, by a ``flock`` on a file of its
own in a directory all sessions share, until the test that picked it ends
(:func:`release_claims`, from tests/conftest.py). A claimed ID is never picked again.
"""

from __future__ import annotations

import fcntl
import os
import random
import tempfile
from collections.abc import Sequence
from pathlib import Path

import pytest

from ros_isolated_test.domain_coordinator import participants, squatters
from ros_isolated_test.domain_coordinator.lock_dir import lock_dir_from_env
from ros_isolated_test.domain_coordinator.lock_files import probe_lock
from ros_isolated_test.domain_coordinator.pool import HIGHEST_VALID_ID
from ros_isolated_test.domain_coordinator.port_guard import port_is_taken

HIGH_IDS = range(215, HIGHEST_VALID_ID + 1)
#: Where the sessions of this suite on this machine claim the IDs their tests picked.
CLAIMS = Path(tempfile.gettempdir()) / "ros-isolated-test-suite-claims"

#: The claims this process holds (ID -> descriptor of its locked file), for the running test.
_claimed: dict[int, int] = {}


def _claim(domain_id: int) -> bool:
    """Claim ``domain_id`` for the running test; False when this or another session has it."""
    if domain_id in _claimed:
        return False
    if not CLAIMS.is_dir():
        CLAIMS.mkdir(exist_ok=True)
        os.chmod(CLAIMS, 0o1777)  # every user's sessions claim here (the mode beats umask)
    fd = os.open(CLAIMS / str(domain_id), os.O_RDONLY | os.O_CREAT | os.O_CLOEXEC, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return False
    _claimed[domain_id] = fd
    return True


def release_claims() -> None:
    """Let other sessions pick the IDs the test that just ended picked."""
    while _claimed:
        os.close(_claimed.popitem()[1])


def in_use(domain_id: int, squatted: set[int]) -> bool:
    """Held by a runner (default or current lock dir), its port bound, or squatted.

    ``squatted`` also holds the IDs a DDS participant is bound to (the coordinator
    refuses those too).
    """
    if domain_id in squatted or port_is_taken(domain_id):
        return True
    lock_dirs = {lock_dir_from_env({}), lock_dir_from_env()}
    return any(path.is_dir() and probe_lock(path, domain_id) for path in lock_dirs)


def free_ids(count: int, candidates: Sequence[int] = HIGH_IDS) -> list[int]:
    """``count`` IDs free now, at random: from ``candidates`` first, then any other valid ID.

    Not finding them is a failure, never a skip: a machine with fewer than ``count`` of
    232 IDs free is not a missing capability.
    """
    # In random order: other sessions of this suite pick beside us at the same moment, and
    # all taking the first free IDs would collide between the check and the reservation.
    others = [i for i in range(1, HIGHEST_VALID_ID + 1) if i not in candidates]
    everything = [
        *random.sample(list(candidates), len(candidates)),
        *random.sample(others, len(others)),
    ]
    squatted = set(squatters.scan(set(everything))) | set(participants.bound_domains())
    free: list[int] = []
    for domain_id in everything:
        if not in_use(domain_id, squatted) and _claim(domain_id):
            free.append(domain_id)
            if len(free) == count:
                return free
    pytest.fail(f"only {len(free)} domain IDs are free on this machine, {count} needed")
