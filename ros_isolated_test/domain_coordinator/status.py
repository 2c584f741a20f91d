"""What ``ros-isolated-test status`` reports: every ID of the pool that is in use."""

from __future__ import annotations

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


def held_domains(lock_dir: Path, pool: tuple[int, ...]) -> list[HeldDomain]:
    """Probe every ID of the pool without keeping anything.

    A probe takes the free lock for an instant; a runner that looks at that moment just
    moves on to the next ID, so probing never makes a test fail.
    """
    held: list[HeldDomain] = []
    if not lock_dir.is_dir():
        return held
    for domain_id in pool:
        if lock_path(lock_dir, domain_id).exists():
            lock = try_lock(lock_dir, domain_id)
            if lock is None:
                records = holder.read_records(lock_dir, domain_id)
                held.append(HeldDomain(domain_id, "lock", records[0] if records else None))
                continue
            lock.release()
        if port_guard.port_is_taken(domain_id):
            held.append(HeldDomain(domain_id, "port", None))
    return held
