"""2. Acquisition under contention: 100 processes asking for a domain ID at the same moment.

This is what ``ctest -j100`` (or several CI jobs on one machine) does to a coordinator.
Interpreter start-up and imports are kept out of the measurement: every process first
imports its coordinator and says so, then all wait on one pipe; closing the pipe's
write end releases them at once (EOF reaches every reader together). Each process then
reports when it asked and when it held its ID (CLOCK_MONOTONIC, one clock for the whole
machine), and keeps holding until every process has reported, so the IDs are checked
to be distinct while all are held at the same time.
"""

from __future__ import annotations

import os
import selectors
import subprocess
import time
from dataclasses import dataclass

from common import (
    OURS,
    RUNNERS,
    UPSTREAM,
    Context,
    Section,
    interleaved,
    median,
    ms,
    percentile,
    progress,
    ratio,
)

PROCESSES = 100
#: Ours gets one ID more than there are processes, as its default pool 1-101 has.
OURS_POOL = range(1, 102)
#: Both children: imports first, then "ready", then the start barrier, then the coordinator.
_PRELUDE = "import os, sys, time\n"
_BARRIER = r"""
hold_fd = int(sys.argv[2])
print("ready", flush=True)
os.read(0, 1)  # the start barrier: returns at EOF, when the parent closes the pipe
asked = time.monotonic()
"""

#: Upstream: domain_coordinator.domain_id(), what run_test_isolated.py calls.
_UPSTREAM_CHILD = (
    _PRELUDE
    + "import domain_coordinator\n"
    + _BARRIER
    + r"""
try:
    with domain_coordinator.domain_id() as domain:
        print(f"held {domain} {asked} {time.monotonic()}", flush=True)
        os.read(hold_fd, 1)  # hold until every process has reported
except RuntimeError as error:
    print(f"failed {asked} {time.monotonic()} {error}", flush=True)
"""
)

#: Ours: DomainCoordinator.reserve(), what the runner calls; it may wait up to 60 s.
_OURS_CHILD = (
    _PRELUDE
    + "from pathlib import Path\n"
    + "from ros_isolated_test.domain_coordinator import DomainCoordinator, PoolExhaustedError\n"
    + "coordinator = DomainCoordinator(\n"
    + f"    lock_dir=Path(sys.argv[1]), pool=range({OURS_POOL.start}, {OURS_POOL.stop})\n"
    + ")\n"
    + _BARRIER
    + r"""
try:
    with coordinator.reserve(["bench"], wait_timeout=60.0) as held:
        print(f"held {held.domain_id} {asked} {time.monotonic()}", flush=True)
        os.read(hold_fd, 1)  # hold until every process has reported
except PoolExhaustedError as error:
    print(f"failed {asked} {time.monotonic()} {error}", flush=True)
"""
)


@dataclass
class Round:
    """One round: every process's wait, the time until the last held its ID, failures."""

    waits: list[float]
    all_held_after: float
    failed: int
    distinct: bool


def _read_lines(procs: list[subprocess.Popen[bytes]], want: int, timeout: float) -> list[str]:
    """One line from each process that gives one within ``timeout``."""
    lines: list[str] = []
    with selectors.DefaultSelector() as selector:
        for proc in procs:
            assert proc.stdout is not None
            selector.register(proc.stdout, selectors.EVENT_READ, proc)
        deadline = time.monotonic() + timeout
        while len(lines) < want and time.monotonic() < deadline:
            for key, _ in selector.select(max(0.0, deadline - time.monotonic())):
                proc = key.data
                assert proc.stdout is not None
                line = proc.stdout.readline().decode()
                selector.unregister(key.fileobj)
                lines.append(line.strip() if line else f"failed exited {proc.poll()}")
    return lines


def one_round(ctx: Context, runner: str, index: int) -> Round:
    """Start 100 children, release them together, collect who got which ID and when."""
    lock_dir = ctx.scratch(f"contention/locks-{index}")
    code = _OURS_CHILD if runner == OURS else _UPSTREAM_CHILD
    start_r, start_w = os.pipe()
    hold_r, hold_w = os.pipe()
    procs: list[subprocess.Popen[bytes]] = []
    try:
        for _ in range(PROCESSES):
            procs.append(
                subprocess.Popen(
                    [ctx.python, "-c", code, str(lock_dir), str(hold_r)],
                    env=ctx.environment(),
                    stdin=start_r,
                    stdout=subprocess.PIPE,
                    pass_fds=(hold_r,),
                )
            )
        os.close(start_r)
        os.close(hold_r)
        ready = _read_lines(procs, PROCESSES, 120.0)
        if len(ready) != PROCESSES or any(line != "ready" for line in ready):
            raise RuntimeError(f"{runner}: children did not all start: {ready[:3]}")
        go = time.monotonic()
        os.close(start_w)  # the start barrier: every child's read returns now
        start_w = -1
        reports = [line.split() for line in _read_lines(procs, PROCESSES, 120.0)]
    finally:
        for fd in (start_w, hold_w):
            if fd >= 0:
                os.close(fd)  # releases the holders
        for proc in procs:
            proc.wait(60)
            assert proc.stdout is not None
            proc.stdout.close()
    held = [report for report in reports if report and report[0] == "held"]
    ids = [int(report[1]) for report in held]
    return Round(
        waits=[float(report[3]) - float(report[2]) for report in held],
        all_held_after=max((float(report[3]) for report in held), default=go) - go,
        failed=PROCESSES - len(held),
        distinct=len(set(ids)) == len(ids),
    )


def run(ctx: Context) -> Section:
    """Interleaved rounds of 100 concurrent acquisitions through each coordinator."""
    rounds = 1 if ctx.quick else 5
    results: dict[str, list[Round]] = {runner: [] for runner in RUNNERS}
    for index, (rep, runner) in enumerate(interleaved(rounds)):
        progress(f"contention: round {rep + 1}/{rounds}, {runner}, {PROCESSES} processes")
        results[runner].append(one_round(ctx, runner, index))
    section = Section(
        f"2. Acquisition under contention: {PROCESSES} processes ask for an ID at once, "
        f"{rounds} round(s) each, interleaved",
        ("", "ours", "upstream", "ours / upstream"),
    )
    all_held = {r: median([x.all_held_after for x in results[r]]) for r in RUNNERS}
    waits = {r: [w for x in results[r] for w in x.waits] for r in RUNNERS}
    p50 = {r: percentile(waits[r], 50) for r in RUNNERS}
    p99 = {r: percentile(waits[r], 99) for r in RUNNERS}
    failed = {r: sum(x.failed for x in results[r]) for r in RUNNERS}
    distinct = {r: all(x.distinct for x in results[r]) for r in RUNNERS}
    section.rows.extend(
        [
            ("all hold distinct IDs after (median over rounds)", ms(all_held[OURS]),
             ms(all_held[UPSTREAM]), ratio(all_held[OURS], all_held[UPSTREAM])),
            ("wait per process, p50", ms(p50[OURS]), ms(p50[UPSTREAM]),
             ratio(p50[OURS], p50[UPSTREAM])),
            ("wait per process, p99", ms(p99[OURS]), ms(p99[UPSTREAM]),
             ratio(p99[OURS], p99[UPSTREAM])),
            ("processes that got no ID", f"{failed[OURS]} of {PROCESSES * rounds}",
             f"{failed[UPSTREAM]} of {PROCESSES * rounds}", ""),
            ("IDs held at once all distinct", "yes" if distinct[OURS] else "**NO**",
             "yes" if distinct[UPSTREAM] else "**NO**", ""),
        ]
    )  # fmt: skip
    section.notes.append(
        f"Ours: `DomainCoordinator(lock_dir=<private>, pool=range(1, 102)).reserve(...)` "
        f"(the default pool has 101 IDs). Upstream: `domain_coordinator.domain_id()`, IDs "
        f"1-100 on TCP ports 32769-32868. Wait = from the call to holding the ID; "
        f'"all hold" = from the release of the start barrier to the last ID held, '
        f"{PROCESSES} processes on {os.cpu_count()} CPUs."
    )
    return section
