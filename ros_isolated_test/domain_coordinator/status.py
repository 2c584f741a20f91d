"""What ``ros-isolated-test status`` reports: every ID of the pool that is in use."""

from __future__ import annotations

import contextlib
import os
import re
from dataclasses import dataclass
from pathlib import Path

from ros_isolated_test.domain_coordinator import holder, port_guard
from ros_isolated_test.domain_coordinator.reservation import lock_path, try_lock


@dataclass(frozen=True)
class HeldDomain:
    """One ID in use: by one of our runners (``via="lock"``) or only its port (``"port"``)."""

    domain_id: int
    via: str
    holder: holder.Holder | None


_LOCK_NAME = re.compile(r"domain-([0-9]+)\.lock")


def held_domains(lock_dir: Path, pool: tuple[int, ...]) -> list[HeldDomain]:
    """Every ID held in the lock directory (any pool), plus the pool's IDs held by port.

    Runners of other users may use other pools, so every lock file counts, not only
    the caller's pool. A probe takes a free lock for an instant; a runner that looks
    at that moment just moves on to the next ID, so probing never makes a test fail.
    """
    candidates = set(pool)
    with contextlib.suppress(OSError):
        for entry in os.scandir(lock_dir):
            match = _LOCK_NAME.fullmatch(entry.name)
            if match:
                candidates.add(int(match.group(1)))
    held: list[HeldDomain] = []
    for domain_id in sorted(candidates):
        if lock_path(lock_dir, domain_id).exists():
            lock_fd = try_lock(lock_dir, domain_id)
            if lock_fd is None:
                records = holder.read_records(lock_dir, domain_id)
                held.append(HeldDomain(domain_id, "lock", records[0] if records else None))
                continue
            os.close(lock_fd)
        if port_guard.port_is_taken(domain_id):
            held.append(HeldDomain(domain_id, "port", None))
    return held
