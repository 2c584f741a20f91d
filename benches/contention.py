"""2. Acquisition under contention: 100 processes asking for a domain ID at the same moment.

This is what ``ctest -j100`` (or several CI jobs on one machine) does to a coordinator.
Interpreter start-up and imports are kept out of the measurement: every process first
imports its coordinator and says so, then all wait on one pipe; closing the pipe's
write end releases them at once (EOF reaches every reader together). Each process then
reports when it asked and when it held its ID (CLOCK_MONOTONIC, one clock for the whole
machine), and keeps holding until every process has reported, so the IDs are checked
to be distinct while all are held at the same time.

Kilted's upstream runner holds its ID in a C++ program, ``run_rmw_isolated``, that it
puts before the test command: the ID is taken in that process, and the first moment it
can be seen held is when the test starts with it. So each Kilted child, after the
barrier, execs ``run_rmw_isolated bash -c <report>``: bash prints the ID it was given
and the time (``$EPOCHREALTIME``, no fork), then holds until all have reported. That
counts one exec of the fixture and one fork+exec of bash (~2 ms of CPU each process)
that ours and Jazzy's in-process calls do not pay: an upper bound for Kilted. (The
fixture's Python binding, ``rmw_test_isolation_start()``, would be in process, but it
costs ~12 ms a call here against ~2 ms for the whole C++ program: not what the runner
pays.) Ours is measured again under the Kilted venv, like with like. All rounds run on a quiet host
and again with 3000 idle processes alive (``idle_scene``).
"""

from __future__ import annotations

import os
import selectors
import shutil
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass

import idle_scene
from common import (
    KILTED,
    KILTED_VENV,
    LABELS,
    OURS,
    OURS_KILTED,
    Context,
    Section,
    at_most,
    interleaved,
    median,
    ms,
    percentile,
    progress,
    quotient,
    ratio,
    verdict,
)
from idle_scene import BUSY, QUIET

PROCESSES = 100
KILTED_FIXTURE = KILTED_VENV / "lib" / "rmw_test_fixture_implementation" / "run_rmw_isolated"
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

#: Kilted: exec run_rmw_isolated, whose test (bash, no fork for the clock) reports the
#: ID it was given; wall clock here, as the clock must cross an exec into bash.
_KILTED_CHILD = (
    _PRELUDE
    + "fixture, bash = sys.argv[3], sys.argv[4]\n"
    + "os.dup2(hold_fd := int(sys.argv[2]), 3)  # the test holds on fd 3\n"
    + _BARRIER.replace("hold_fd = int(sys.argv[2])\n", "")
    + r"""
report = 't=$EPOCHREALTIME; echo "held $ROS_DOMAIN_ID $1 ${t/,/.}"; read -r _ <&3'
asked = time.time()
os.execv(fixture, [fixture, bash, "-c", report, "bash", repr(asked)])
"""
)
CHILDREN = {OURS: _OURS_CHILD, OURS_KILTED: _OURS_CHILD, KILTED: _KILTED_CHILD}


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
    code = CHILDREN.get(runner, _UPSTREAM_CHILD)
    extra = [str(KILTED_FIXTURE), shutil.which("bash") or "bash"] if runner == KILTED else []
    start_r, start_w = os.pipe()
    hold_r, hold_w = os.pipe()
    procs: list[subprocess.Popen[bytes]] = []
    try:
        for _ in range(PROCESSES):
            procs.append(
                subprocess.Popen(
                    [ctx.python_of(runner), "-c", code, str(lock_dir), str(hold_r), *extra],
                    env=ctx.environment(runner),
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
        # Kilted's children stamp the wall clock (it crosses an exec), the others monotonic.
        go = time.time() if runner == KILTED else time.monotonic()
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


def _scene_rows(
    scene: str, got: dict[str, list[Round]], pairs: list[tuple[str, str]]
) -> list[tuple[str, ...]]:
    """The table's rows for one scene: each cell per runner, the ratio per pair."""
    runners = list(got)
    rounds = max((len(x) for x in got.values()), default=0)
    rows: list[tuple[str, ...]] = []
    all_held = {r: median([x.all_held_after for x in got[r]]) for r in runners}
    waits = {r: [w for x in got[r] for w in x.waits] for r in runners}
    p50 = {r: percentile(waits[r], 50) for r in runners}
    p99 = {r: percentile(waits[r], 99) for r in runners}
    failed = {r: sum(x.failed for x in got[r]) for r in runners}
    distinct = {r: all(x.distinct for x in got[r]) for r in runners}
    where = "quiet" if scene == QUIET else f"{idle_scene.IDLE_PROCESSES} idle processes"
    target = "ours / upstream ≤ 1.00: " + ", ".join(
        f"{verdict(at_most(quotient(all_held[o], all_held[u]), 1.0))} ({LABELS[u].split()[0]})"
        for o, u in pairs
    )
    table: list[tuple[str, Callable[[str], str], Callable[[str, str], str], str]] = [
        (f"{where}: all hold distinct IDs after (median over rounds)",
         lambda r: ms(all_held[r]), lambda o, u: ratio(all_held[o], all_held[u]), target),
        (f"{where}: wait per process, p50", lambda r: ms(p50[r]),
         lambda o, u: ratio(p50[o], p50[u]), ""),
        (f"{where}: wait per process, p99", lambda r: ms(p99[r]),
         lambda o, u: ratio(p99[o], p99[u]), ""),
        (f"{where}: processes that got no ID",
         lambda r: f"{failed[r]} of {PROCESSES * rounds}", lambda o, u: "", ""),
        (f"{where}: IDs held at once all distinct",
         lambda r: "yes" if distinct[r] else "**NO**", lambda o, u: "", ""),
    ]  # fmt: skip
    for label, cell, pair_ratio, goal in table:
        cells = [label]
        for ours, upstream in pairs:
            cells += [cell(ours), cell(upstream), pair_ratio(ours, upstream)]
        rows.append((*cells, goal))
    return rows


def run(ctx: Context) -> Section:
    """Interleaved rounds of 100 concurrent acquisitions through each coordinator."""
    rounds = 1 if ctx.quick else 5
    runners = ctx.all_runners()
    results: dict[tuple[str, str], list[Round]] = {
        (scene, r): [] for scene in (QUIET, BUSY) for r in runners
    }
    counter = iter(range(1_000_000))

    def rounds_of(scene: str, n: int) -> None:
        for rep, runner in interleaved(n, runners):
            progress(f"contention: {scene}, round {rep + 1}/{n}, {runner}, {PROCESSES} processes")
            results[scene, runner].append(one_round(ctx, runner, next(counter)))

    scene_note = idle_scene.in_scenes(ctx.python, ctx.work, rounds, rounds_of)
    pairs, section = ctx.pair_section(
        f"2. Acquisition under contention: {PROCESSES} processes ask for an ID at once, "
        f"{rounds} round(s) each per scene, interleaved",
    )
    for scene in (QUIET, BUSY):
        section.rows.extend(_scene_rows(scene, {r: results[scene, r] for r in runners}, pairs))
    section.notes.append(
        f"Ours: `DomainCoordinator(lock_dir=<private>, pool=range(1, 102)).reserve(...)` "
        f"(the default pool has 101 IDs), under each venv. Jazzy upstream: "
        f"`domain_coordinator.domain_id()`, IDs 1-100 on TCP ports 32769-32868. Kilted "
        f"upstream: each process execs `run_rmw_isolated bash -c <report>` (an upper bound: "
        f"it includes that exec and bash's start), IDs 1-101 on 127.0.0.1:32769-32869, first "
        f"port tried seeded by the pid. Wait = from the call to holding the ID; "
        f'"all hold" = from the release of the start barrier to the last ID held, '
        f"{PROCESSES} processes on {os.cpu_count()} CPUs. Busy host: {scene_note}."
    )
    for runner, why in ctx.missing.items():
        section.notes.append(f"{LABELS[runner]}: not measured: {why}.")
    return section
