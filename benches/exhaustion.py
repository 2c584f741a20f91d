"""3. Exhaustion: twice as many concurrent tests as IDs in the pool.

A pool of two for every runner. Ours is told so (``ROS_ISOLATED_TEST_DOMAINS`` names two
free IDs). Neither upstream has such a setting: Jazzy's pool is whatever ports of
32769..32868 it can bind (0.0.0.0, IDs 1-100, tried in order from 1), Kilted's
run_rmw_isolated whatever of 127.0.0.1:32769..32869 it can bind (IDs 1-101, starting at
an offset seeded by its pid; found in rmw_test_fixture_default.c and checked here: a
wildcard bind of the port shuts it out too). So the benchmark binds all of 32769..32869
except the two ports of the same two IDs, for every runner alike, for the whole
benchmark. (That is also how upstream meets an exhausted machine in real life: every
port already taken.) Neither upstream waits for an ID: the surplus fails at once.
Four tests that each sleep one second then start at once through the runner, the way
``ctest -j4`` starts them.
"""

from __future__ import annotations

import contextlib
import socket
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from common import (
    LABELS,
    Context,
    Section,
    interleaved,
    median,
    progress,
    ratio,
    secs,
    verdict,
)

PORT_BASE = 32768
#: Jazzy's domain_coordinator uses 1-100, Kilted's rmw_test_fixture 1-101.
UPSTREAM_IDS = range(1, 102)
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
    env = ctx.environment(runner, ROS_ISOLATED_TEST_DOMAINS=",".join(str(i) for i in pool))
    results = [scratch / f"test{n}.xml" for n in range(TESTS)]
    start = time.perf_counter()
    procs = ctx.start_runners(runner, results, ("sleep", f"{SLEEP_SECONDS:g}"), env)
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
    runners = ctx.all_runners()
    pool = _free_ids(POOL_SIZE)
    if len(pool) < POOL_SIZE:
        raise RuntimeError("exhaustion: fewer than two free domain IDs on this machine")
    results: dict[str, list[Round]] = {runner: [] for runner in runners}
    with _ports_blocked_except(set(pool)) as blocked:
        for index, (rep, runner) in enumerate(interleaved(rounds, runners)):
            progress(f"exhaustion: round {rep + 1}/{rounds}, {runner}")
            results[runner].append(one_round(ctx, runner, pool, index))
    ideal = TESTS * SLEEP_SECONDS / POOL_SIZE
    wall = {r: median([x.wall for x in results[r]]) for r in runners}
    failed = {r: sum(x.failed for x in results[r]) for r in runners}
    written = {r: sum(x.results_written for x in results[r]) for r in runners}
    total = TESTS * rounds
    pairs, section = ctx.pair_section(
        f"3. Exhaustion: {TESTS} concurrent {SLEEP_SECONDS:g} s tests on a pool of "
        f"{POOL_SIZE} IDs, {rounds} round(s) each, interleaved",
    )
    none_failed = ", ".join(f"{verdict(failed[o] == 0)} ({LABELS[u].split()[0]})" for o, u in pairs)
    table: list[tuple[str, Callable[[str], str], Callable[[str, str], str], str]] = [
        ("tests failed", lambda r: f"{failed[r]} of {total}", lambda o, u: "",
         f"ours fails none: {none_failed}"),
        ("result files left", lambda r: f"{written[r]} of {total}", lambda o, u: "", ""),
        ("wall time, first start to last exit (median)", lambda r: secs(wall[r]),
         lambda o, u: ratio(wall[o], wall[u]), ""),
        (f"ideal: work / pool size = {TESTS} x {SLEEP_SECONDS:g} s / {POOL_SIZE}",
         lambda r: secs(ideal), lambda o, u: "", ""),
        ("wall / ideal", lambda r: ratio(wall[r], ideal), lambda o, u: "", ""),
    ]  # fmt: skip
    for label, cell, pair_ratio, goal in table:
        cells = [label]
        for ours, upstream in pairs:
            cells += [cell(ours), cell(upstream), pair_ratio(ours, upstream)]
        section.rows.append((*cells, goal))
    section.notes.append(
        f"Pool: IDs {pool[0]} and {pool[1]} (ours: `ROS_ISOLATED_TEST_DOMAINS="
        f"{pool[0]},{pool[1]}`; for all, the other {blocked} of ports 32769-32869 bound by "
        f"the benchmark, which confines Jazzy's domain_coordinator (IDs 1-100) and Kilted's "
        f"run_rmw_isolated (IDs 1-101) to the same two). Upstream's wall time is short "
        f"because it fails the surplus at once (Kilted: `Failed to acquire port lock`, exit "
        f"1); ours queues them (first come, first served), so its wall time above the ideal "
        f"is runner start-up plus queue hand-over. The ratio compares a queue with a "
        f"refusal: it has no target."
    )
    for runner, why in ctx.missing.items():
        section.notes.append(f"{LABELS[runner]}: not measured: {why}.")
    return section
