"""Processes a dead holder left on its ID: looked for only when a holder died holding it.

A runner that releases an ID has ended its test's whole tree first (survivors it could
not end are named in a block record), so after a clean release nothing of the test
can still talk on the ID. Only a holder that died holding the ID (SIGKILL, a crash,
the machine's OOM killer) may have left processes behind, and it says so by what it
did not do: its holder record, written when it took the ID and removed when it lets
go, is still in the lock directory, newer than any release of the ID. For such an ID,
and only for it, the coordinator scans ``/proc`` for processes carrying it in
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
    every record of the ID is a dead holder's. A record no newer than the ID's last
    release was left by a holder whose successor has since run and released cleanly
    (it looked, see :func:`escaped_processes`); an equal time counts as newer, so a
    coarse file clock errs on the side of looking. Anything with a record's name
    counts, whoever planted it: a planted file costs a scan, never an ID.
    """
    prefix = f"domain-{domain_id}."
    recorded = released = 0.0
    with contextlib.suppress(OSError):
        for entry in os.scandir(lock_dir):
            name = entry.name
            if not name.startswith(prefix):
                continue
            is_record = name.endswith(".holder.json")
            if not is_record and not name.endswith(".released"):
                continue
            try:
                mtime = entry.stat(follow_symlinks=False).st_mtime
            except OSError:
                continue
            if is_record:
                recorded = max(recorded, mtime or 1.0)
            else:
                released = max(released, mtime)
    return recorded > 0.0 and recorded >= released


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
