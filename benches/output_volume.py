"""4. Output volume: a test printing 10 to 300 MB, wall time and peak memory of each runner.

A chatty test (debug logging, a launch test echoing every node) must cost time in
proportion to what it prints and no memory beyond a fixed amount. The test is
``yes <80-byte line> | head -c N`` so that producing the bytes costs next to nothing;
the runner's output is read from a pipe and thrown away, as ctest reads it.

Two cases, because upstream behaves very differently in them:

- the test passes (exit 0, ``--generate-result-on-success``): upstream keeps every line
  in memory but writes none of it; time is linear, memory grows with the output;
- the test fails without writing a result file (exit 1), the case where output matters:
  upstream puts the whole output into the result file it writes, and that step grows
  quadratically (about 12 s for 20 MB here), so upstream gets at most 40 MB of it.
  Ours keeps the last 64 KiB for the result file in both cases.
"""

from __future__ import annotations

import itertools
import subprocess

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
    run_timed,
    secs,
)

MB = 1_000_000
SIZES_MB = (10, 40, 100, 300)
#: Above this a failing test is not run through upstream: it grows quadratically.
UPSTREAM_CAP_MB = 40
#: In --quick mode upstream gets only the smallest size (a failing 40 MB takes ~50 s).
UPSTREAM_QUICK_CAP_MB = 10
LINE = "x" * 79  # `yes` adds the newline: 80 bytes a line
RSS_TARGET_MIB = 100
RATE_TARGET = 100.0
CASES = ("passes", "fails")


def producer(size_mb: int, case: str) -> tuple[str, ...]:
    """The test command: print exactly ``size_mb`` MB of 80-byte lines, then pass or fail."""
    ending = "; exit 1" if case == "fails" else ""
    return ("sh", "-c", f"yes {LINE} | head -c {size_mb * MB}{ending}")


def _runs_upstream(size: int, case: str, quick: bool) -> str | None:
    """None if upstream runs this size and case, else why not."""
    if quick and size > UPSTREAM_QUICK_CAP_MB:
        return "skipped in --quick"
    if case == "fails" and size > UPSTREAM_CAP_MB:
        return "skipped: quadratic"
    return None


def _rate(walls: dict[int, float], low: int, high: int) -> float | None:
    """MB/s from ``low`` to ``high`` MB: free of the fixed start-up; None if noise hid it."""
    spent = walls[high] - walls[low]
    return (high - low) / spent if spent > 0 else None


def _shown(rate: float | None) -> str:
    """A rate, or a dash where the larger size happened to run faster than the smaller."""
    return f"{rate:.0f}" if rate is not None else "- (noise)"


def run(ctx: Context) -> Section:
    """Each size and case through each runner that takes it, interleaved; medians."""
    reps = 1 if ctx.quick else 3
    scratch = ctx.scratch("output")
    env = ctx.environment()
    walls: dict[tuple[str, str, int], list[float]] = {}
    rss: dict[tuple[str, str, int], list[int]] = {}
    unexpected: list[str] = []
    baseline: dict[int, float] = {}
    for size in SIZES_MB:
        baseline[size] = median(
            [run_timed(producer(size, "passes"), env, subprocess.PIPE).seconds for _ in range(reps)]
        )
        for case in CASES:
            runners = RUNNERS if _runs_upstream(size, case, ctx.quick) is None else (OURS,)
            for rep, runner in interleaved(reps, runners):
                progress(f"output volume: {size} MB, test {case}, {runner} ({rep + 1}/{reps})")
                result = scratch / f"{runner}-{case}-{size}.xml"
                command = ctx.runner_command(runner, result, producer(size, case))
                outcome = run_timed(command, env, subprocess.PIPE)
                key = (runner, case, size)
                walls.setdefault(key, []).append(outcome.seconds)
                rss.setdefault(key, []).append(outcome.max_rss_kib)
                expected = 0 if case == "passes" else 1
                if outcome.returncode != expected or not result.is_file():
                    unexpected.append(
                        f"{runner}, {size} MB, test {case}: exit code {outcome.returncode}"
                        f"{'' if result.is_file() else ', no result file'}"
                    )
    section = Section(
        f"4. Output volume: a test printing N MB, read from a pipe ({reps} run(s) each, median)",
        ("test prints", "ours: wall", "ours: MB/s", "ours: peak RSS", "upstream: wall",
         "upstream: MB/s", "upstream: peak RSS", "wall ours / upstream"),
    )  # fmt: skip
    for case in CASES:
        for size in SIZES_MB:
            cells = [f"{size} MB, then {'passes' if case == 'passes' else 'fails (exit 1)'}"]
            for runner in RUNNERS:
                key = (runner, case, size)
                if key not in walls:
                    cells.extend([_runs_upstream(size, case, ctx.quick) or "", "", ""])
                    continue
                wall = median(walls[key])
                peak = median([float(kib) for kib in rss[key]]) / 1024
                cells.extend([secs(wall), f"{size / wall:.0f}", f"{peak:.0f} MiB"])
            ours_wall = median(walls[(OURS, case, size)])
            cells.append(ratio(ours_wall, median(walls.get((UPSTREAM, case, size), []))))
            section.rows.append(cells)
    steps = ", ".join(f"{low}->{high}" for low, high in itertools.pairwise(SIZES_MB))
    first, last = SIZES_MB[0], SIZES_MB[-1]
    described: list[str] = []
    for case in CASES:
        walls_of = {size: median(walls[(OURS, case, size)]) for size in SIZES_MB}
        steps_rates = ", ".join(
            _shown(_rate(walls_of, low, high)) for low, high in itertools.pairwise(SIZES_MB)
        )
        described.append(
            f"test {case}: {_shown(_rate(walls_of, first, last))} MB/s from {first} to {last} MB "
            f"(per step {steps}: {steps_rates})"
        )
    peaks = [max(values) / 1024 for (runner, _, _), values in rss.items() if runner == OURS]
    section.notes.append(
        f"Targets for ours: linear, at least {RATE_TARGET:.0f} MB/s, peak RSS under "
        f"{RSS_TARGET_MIB} MB at any size. The MB/s column includes the runner's fixed "
        f"start-up; ours' rate on the added output alone, which is constant when time is "
        f"linear: " + "; ".join(described) + f". Highest peak RSS of ours: {max(peaks):.0f} "
        "MiB. The producer alone, read from a pipe: "
        + ", ".join(f"{secs(baseline[size])} for {size} MB" for size in SIZES_MB)
        + ". Peak RSS is wait4's ru_maxrss of the runner process (its test's processes "
        "stay at a few MB)."
    )
    for item in unexpected:
        section.notes.append(f"**Unexpected: {item}.**")
    return section
