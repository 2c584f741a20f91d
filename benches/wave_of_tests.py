"""7. Wave: 60 no-op tests started at once through the RUNNER, time until all have finished.

``ctest -j60`` on a suite of quick tests, or a CI host running several jobs: every
runner starts, reserves an ID, runs its test and leaves at about the same moment. This
is the per-test overhead (1) and the contention (2) together, at the scale of whole
runner processes on 2 CPUs: start-up, imports, the reservation, the test, the result
file. Taken on a quiet host and with 3000 idle processes
alive; the question is whether ours keeps its lead over upstream when the host is busy.
"""

from __future__ import annotations

import functools
import os
import time
from collections import defaultdict
from collections.abc import Callable

import idle_scene
from common import (
    LABELS,
    Context,
    Section,
    at_most,
    interleaved,
    median,
    progress,
    quotient,
    ratio,
    secs,
    verdict,
)
from idle_scene import BUSY, QUIET

TESTS = 60
NOOP = ("true",)
#: The busy host's ours/upstream may exceed the quiet one's by this factor at most.
BUSY_TARGET = 1.10


def one_wave(ctx: Context, runner: str, index: int) -> tuple[float, int, int]:
    """Start all tests at once; (first start to last exit, failed, result files left)."""
    scratch = ctx.scratch(f"wave/{index}-{runner}")
    env = ctx.environment(runner)
    results = [scratch / f"test{n}.xml" for n in range(TESTS)]
    start = time.perf_counter()
    procs = ctx.start_runners(runner, results, NOOP, env)
    codes = [proc.wait(600) for proc in procs]
    wall = time.perf_counter() - start
    failed = sum(1 for code in codes if code != 0)
    return wall, failed, sum(1 for result in results if result.is_file())


def run(ctx: Context) -> Section:
    """Interleaved waves through each runner, quiet and busy."""
    reps = 1 if ctx.quick else 5
    runners = ctx.all_runners()
    walls: dict[tuple[str, str], list[float]] = defaultdict(list)
    failed: dict[tuple[str, str], int] = defaultdict(int)
    written: dict[tuple[str, str], int] = defaultdict(int)
    counter = iter(range(1_000_000))

    def waves(scene: str, n: int) -> None:
        for rep, runner in interleaved(n, runners):
            progress(f"wave: {scene}, {rep + 1}/{n}, {TESTS} tests through {runner}")
            wall, bad, left = one_wave(ctx, runner, next(counter))
            walls[scene, runner].append(wall)
            failed[scene, runner] += bad
            written[scene, runner] += left

    scene_note = idle_scene.in_scenes(ctx.python, ctx.work, reps, waves)
    wall = {key: median(values) for key, values in walls.items()}
    pairs, section = ctx.pair_section(
        f"7. Wave: {TESTS} no-op tests started at once through the RUNNER, {reps} wave(s) "
        f"each per scene, interleaved",
    )
    pair_ratio = {
        (scene, o): quotient(wall.get((scene, o), nan()), wall.get((scene, u), nan()))
        for scene in (QUIET, BUSY)
        for o, u in pairs
    }

    def row(
        label: str, cell: Callable[[str], str], ratio_of: Callable[[str, str], str], goal: str = ""
    ) -> None:
        cells = [label]
        for ours, upstream in pairs:
            cells += [cell(ours), cell(upstream), ratio_of(ours, upstream)]
        section.rows.append((*cells, goal))

    for scene in (QUIET, BUSY):
        where = "quiet" if scene == QUIET else f"{idle_scene.IDLE_PROCESSES} idle processes"
        goal = "ours / upstream ≤ 1.00: " + ", ".join(
            f"{verdict(at_most(pair_ratio[scene, o], 1.0))} ({LABELS[u].split()[0]})"
            for o, u in pairs
        )
        row(
            f"{where}: all {TESTS} finished after (median)",
            functools.partial(_cell_wall, wall, scene),
            functools.partial(_cell_ratio, pair_ratio, scene),
            goal,
        )
        row(
            f"{where}: tests failed / result files left",
            functools.partial(_cell_counts, failed, written, scene, TESTS * reps),
            _blank,
        )
    held = ", ".join(
        f"{verdict(at_most(quotient(pair_ratio[BUSY, o], pair_ratio[QUIET, o]), BUSY_TARGET))}"
        f" ({LABELS[u].split()[0]})"
        for o, u in pairs
    )
    row("busy / quiet",
        lambda r: ratio(wall.get((BUSY, r), nan()), wall.get((QUIET, r), nan())),
        lambda o, u: ratio(pair_ratio[BUSY, o], pair_ratio[QUIET, o]),
        f"ours / upstream busy ≤ {BUSY_TARGET:.2f} x quiet: {held}")  # fmt: skip
    section.notes.append(
        f"All {TESTS} runners are started together (`{TESTS}` Popen calls in a row, as "
        f"`ctest -j{TESTS}` starts them), each running `true` with "
        f"`--generate-result-on-success`; the time is from the first start to the last exit, "
        f"on {len(os.sched_getaffinity(0))} CPUs. In the last row, the ratio column is the "
        f"busy ours/upstream over the quiet one: 1.00 means ours keeps its lead on a busy "
        f"host. Busy host: {scene_note}."
    )
    for runner, why in ctx.missing.items():
        section.notes.append(f"{LABELS[runner]}: not measured: {why}.")
    return section


def _cell_wall(wall: dict[tuple[str, str], float], scene: str, runner: str) -> str:
    return secs(wall.get((scene, runner), nan()))


def _cell_ratio(pair_ratio: dict[tuple[str, str], float], scene: str, ours: str, _: str) -> str:
    return ratio(pair_ratio[scene, ours], 1.0)


def _cell_counts(
    failed: dict[tuple[str, str], int],
    written: dict[tuple[str, str], int],
    scene: str,
    total: int,
    runner: str,
) -> str:
    return f"{failed[scene, runner]} / {written[scene, runner]} of {total}"


def _blank(_ours: str, _upstream: str) -> str:
    return ""


def nan() -> float:
    """A missing figure."""
    return float("nan")
