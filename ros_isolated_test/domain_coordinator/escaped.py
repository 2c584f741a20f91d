"""Processes a dead holder left on its ID: looked for only when a holder died holding it.

A runner that releases an ID has ended its test's whole tree first (survivors it could
not end are named in a block record), so after a clean release nothing of the test
can still talk on the ID. Only a holder that died holding the ID (SIGKILL, a crash,
the machine's OOM killer) may have left processes behind, and it says so by what it
did not do: its holder record, written when it took the ID and removed when it lets
go, is still in the lock directory, newer than any release of the ID by its user (a
runner that could not record its test's survivors leaves it the same way). For such an
ID, and only for it, the coordinator scans ``/proc`` for processes carrying it in
ROS_DOMAIN_ID (a cost that grows with the machine's processes); what the scan finds is
written down as a block record, so the runners after it check those processes by PID
instead of scanning again. Every other reservation costs no look at other processes.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from ros_isolated_test.domain_coordinator import squatters
from ros_isolated_test.domain_coordinator.block import write_block
from ros_isolated_test.process import proc


def died_holding(lock_dir: Path, domain_id: int) -> bool:
    """Whether a holder of the ID left its record behind: it died without releasing.

    Call it while holding the ID (lock and port): no live runner can hold it then, so
    every record of the ID is a dead holder's. A record counts as dealt with once a
    release of the ID came after it by its own user or by root, the users whose look
    (see :func:`escaped_processes`) could see that holder's processes: another user
    cannot read their environments. Times are change times, which no one can set back
    or forward with utime, so a planted stamp cannot clear a record; an equal time
    counts as later for the record, so a coarse file clock errs on the side of looking.
    Anything with a record's name counts, whoever planted it: a planted file costs a
    scan, never an ID.
    """
    prefix = f"domain-{domain_id}."
    records: list[tuple[int, float]] = []
    released: dict[int, float] = {}
    with contextlib.suppress(OSError):
        for entry in os.scandir(lock_dir):
            name = entry.name
            if not name.startswith(prefix):
                continue
            is_record = name.endswith(".holder.json")
            if not is_record and not name.endswith(".released"):
                continue
            try:
                info = entry.stat(follow_symlinks=False)
            except OSError:
                continue
            if is_record:
                records.append((info.st_uid, info.st_ctime))
            else:
                released[info.st_uid] = max(released.get(info.st_uid, 0.0), info.st_ctime)
    return any(max(released.get(uid, 0.0), released.get(0, 0.0)) <= when for uid, when in records)


def escaped_processes(lock_dir: Path, domain_id: int) -> list[squatters.Squatter]:
    """Live processes with the ID in ROS_DOMAIN_ID, when a holder died holding it.

    No scan at all when the ID's last holder released it (the common case). When the
    scan finds processes, a block record names them (best effort), so the ID stays
    blocked for every runner by one lstat and a PID check while they live.
    """
    if not died_holding(lock_dir, domain_id):
        return []
    found = squatters.scan({domain_id}).get(domain_id, [])
    if found:
        stats = [stat for squatter in found if (stat := proc.read_stat(squatter.pid))]
        with contextlib.suppress(OSError):
            write_block(lock_dir, domain_id, stats)
    return found
