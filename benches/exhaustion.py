"""3. Exhaustion: twice as many concurrent tests as IDs in the pool.

A pool of two for both runners. Ours is told so (``ROS_ISOLATED_TEST_DOMAINS`` names two
free IDs). Upstream has no such setting: its pool is whatever ports of 32769..32868 it
can bind, so the benchmark binds all of them except the two that belong to the same two
IDs, for both runners alike, for the whole benchmark. (That is also how upstream meets
an exhausted machine in real life: every port already taken.) Four tests that each sleep
one second then start at once through the runner, the way ``ctest -j4`` starts them.
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass

from common import (
    OURS,
    RUNNERS,
    UPSTREAM,
    Context,
    Section,
    interleaved,
    median,
    progress,
    ratio,
    secs,
)

PORT_BASE = 32768
UPSTREAM_IDS = range(1, 101)
POOL_SIZE = 2
TESTS = 4
SLEEP_SECONDS = 1.0


@dataclass
class Round:
    """One round: wall time from the first start to the last exit, and who failed."""

    wall: float
    failed: int
    results_written: int


def _free_ids(count: int) -> list[int]:
    """IDs whose port is free and that no live process carries in ROS_DOMAIN_ID.

    Ours skips IDs that a live process uses (an escaped test, a shell's export), so both
    runners get two IDs that are free for both.
    """
    from ros_isolated_test.domain_coordinator import squatters

    busy = squatters.scan(set(UPSTREAM_IDS))
    free: list[int] = []
    for domain_id in UPSTREAM_IDS:
        if domain_id in busy:
            continue
        with contextlib.suppress(OSError), socket.socket() as probe:
            probe.bind(("", PORT_BASE + domain_id))
            free.append(domain_id)
            if len(free) == count:
                break
    return free


@contextlib.contextmanager
def _ports_blocked_except(keep: set[int]) -> Iterator[int]:
    """Bind every upstream port but those of ``keep``, as upstream itself binds them."""
    held: list[socket.socket] = []
    try:
        for domain_id in UPSTREAM_IDS:
            if domain_id in keep:
                continue
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            try:
                sock.bind(("", PORT_BASE + domain_id))
            except OSError:
                sock.close()  # already taken by someone else: blocked all the same
                continue
            held.append(sock)
        yield len(held)
    finally:
        for sock in held:
            sock.close()


def one_round(ctx: Context, runner: str, pool: list[int], index: int) -> Round:
    """Start four runners at once, each running ``sleep 1``; wait for all of them."""
    scratch = ctx.scratch(f"exhaustion/{index}-{runner}")
    env = ctx.environment(ROS_ISOLATED_TEST_DOMAINS=",".join(str(i) for i in pool))
    results = [scratch / f"test{n}.xml" for n in range(TESTS)]
    start = time.perf_counter()
    procs = [
        subprocess.Popen(
            ctx.runner_command(runner, result, ("sleep", f"{SLEEP_SECONDS:g}")),
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.STDOUT,
        )
        for result in results
    ]
    codes = [proc.wait(300) for proc in procs]
    wall = time.perf_counter() - start
    return Round(
        wall=wall,
        failed=sum(1 for code in codes if code != 0),
        results_written=sum(1 for result in results if result.is_file()),
    )


def run(ctx: Context) -> Section:
    """Interleaved rounds of four one-second tests on a pool of two, for each runner."""
    rounds = 1 if ctx.quick else 5
    pool = _free_ids(POOL_SIZE)
    if len(pool) < POOL_SIZE:
        raise RuntimeError("exhaustion: fewer than two free domain IDs on this machine")
    results: dict[str, list[Round]] = {runner: [] for runner in RUNNERS}
    with _ports_blocked_except(set(pool)) as blocked:
        for index, (rep, runner) in enumerate(interleaved(rounds)):
            progress(f"exhaustion: round {rep + 1}/{rounds}, {runner}")
            results[runner].append(one_round(ctx, runner, pool, index))
    ideal = TESTS * SLEEP_SECONDS / POOL_SIZE
    wall = {r: median([x.wall for x in results[r]]) for r in RUNNERS}
    failed = {r: sum(x.failed for x in results[r]) for r in RUNNERS}
    written = {r: sum(x.results_written for x in results[r]) for r in RUNNERS}
    total = TESTS * rounds
    section = Section(
        f"3. Exhaustion: {TESTS} concurrent {SLEEP_SECONDS:g} s tests on a pool of "
        f"{POOL_SIZE} IDs, {rounds} round(s) each, interleaved",
        ("", "ours", "upstream", "ours / upstream"),
    )
    section.rows.extend(
        [
            ("tests failed", f"{failed[OURS]} of {total}", f"{failed[UPSTREAM]} of {total}", ""),
            ("result files left", f"{written[OURS]} of {total}",
             f"{written[UPSTREAM]} of {total}", ""),
            ("wall time, first start to last exit (median)", secs(wall[OURS]),
             secs(wall[UPSTREAM]), ratio(wall[OURS], wall[UPSTREAM])),
            (f"ideal: work / pool size = {TESTS} x {SLEEP_SECONDS:g} s / {POOL_SIZE}",
             secs(ideal), secs(ideal), ""),
            ("wall / ideal", ratio(wall[OURS], ideal), ratio(wall[UPSTREAM], ideal), ""),
        ]
    )  # fmt: skip
    section.notes.append(
        f"Pool: IDs {pool[0]} and {pool[1]} (ours: `ROS_ISOLATED_TEST_DOMAINS="
        f"{pool[0]},{pool[1]}`; for both, the other {blocked} of upstream's ports "
        f"32769-32868 bound by the benchmark). Upstream's wall time is short because it "
        f"fails the surplus at once; ours queues them (first come, first served), so its "
        f"wall time above the ideal is runner start-up plus queue hand-over."
    )
    return section
