"""4. Output volume: a test printing 10 to 300 MB, wall time and peak memory of each runner.

A chatty test (debug logging, a launch test echoing every node) must cost time in
proportion to what it prints and no memory beyond a fixed amount. The test is
``yes <80-byte line> | head -c N`` so that producing the bytes costs next to nothing;
the runner's output goes to /dev/null, as ctest would read it from a pipe. Upstream
keeps every line in a string and grows quadratically, so it only gets the small sizes.
"""

from __future__ import annotations

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
#: Above this upstream is not run: it takes about 12 s for 20 MB here and grows quadratically.
UPSTREAM_CAP_MB = 40
#: In --quick mode upstream gets only the smallest size (40 MB alone would take ~50 s).
UPSTREAM_QUICK_CAP_MB = 10
LINE = "x" * 79  # `yes` adds the newline: 80 bytes a line
RSS_TARGET_MB = 100
RATE_TARGET = 100.0


def producer(size_mb: int) -> tuple[str, ...]:
    """The test command: print exactly ``size_mb`` MB of 80-byte lines."""
    return ("sh", "-c", f"yes {LINE} | head -c {size_mb * MB}")


def run(ctx: Context) -> Section:
    """Each size through each runner that takes it, interleaved; median wall and peak RSS."""
    reps = 1 if ctx.quick else 3
    cap = UPSTREAM_QUICK_CAP_MB if ctx.quick else UPSTREAM_CAP_MB
    scratch = ctx.scratch("output")
    env = ctx.environment()
    walls: dict[tuple[str, int], list[float]] = {}
    rss: dict[tuple[str, int], list[int]] = {}
    failures: list[str] = []
    baseline: dict[int, float] = {}
    for size in SIZES_MB:
        baseline[size] = median(
            [run_timed(producer(size), env).seconds for _ in range(reps)]
        )
        runners = RUNNERS if size <= cap else (OURS,)
        for rep, runner in interleaved(reps, runners):
            progress(f"output volume: {size} MB through {runner} ({rep + 1}/{reps})")
            result = scratch / f"{runner}-{size}.xml"
            outcome = run_timed(ctx.runner_command(runner, result, producer(size)), env)
            walls.setdefault((runner, size), []).append(outcome.seconds)
            rss.setdefault((runner, size), []).append(outcome.max_rss_kib)
            if outcome.returncode != 0 or not result.is_file():
                failures.append(f"{runner} at {size} MB exited {outcome.returncode}")
    section = Section(
        f"4. Output volume: a test printing N MB ({reps} run(s) each, median)",
        ("output", "ours: wall", "ours: MB/s", "ours: peak RSS", "upstream: wall",
         "upstream: MB/s", "upstream: peak RSS", "wall ours / upstream"),
    )  # fmt: skip
    for size in SIZES_MB:
        cells = [f"{size} MB"]
        for runner in RUNNERS:
            key = (runner, size)
            if key not in walls:
                why = "skipped in --quick" if size <= UPSTREAM_CAP_MB else "skipped: quadratic"
                cells.extend([why, "", ""])
                continue
            wall = median(walls[key])
            peak = median([float(kib) for kib in rss[key]]) / 1024
            cells.extend([secs(wall), f"{size / wall:.0f}", f"{peak:.0f} MiB"])
        ours_wall = median(walls[(OURS, size)])
        up_wall = median(walls.get((UPSTREAM, size), []))
        cells.append(ratio(ours_wall, up_wall))
        section.rows.append(cells)
    first, last = SIZES_MB[0], SIZES_MB[-1]
    per_mb_first = median(walls[(OURS, first)]) / first
    per_mb_last = median(walls[(OURS, last)]) / last
    rates = [size / median(walls[(OURS, size)]) for size in SIZES_MB]
    peaks = [max(rss[(OURS, size)]) / 1024 for size in SIZES_MB]
    section.notes.append(
        f"Targets for ours: linear (time per MB at {last} MB / at {first} MB = "
        f"{per_mb_last / per_mb_first:.2f}; 1.00 is linear, below 1 is start-up spread "
        f"thinner), at least {RATE_TARGET:.0f} MB/s (lowest: {min(rates):.0f}), peak RSS "
        f"under {RSS_TARGET_MB} MB at any size (highest: {max(peaks):.0f} MiB). The "
        f"producer alone to /dev/null: "
        + ", ".join(f"{secs(baseline[size])} for {size} MB" for size in SIZES_MB)
        + ". Peak RSS is wait4's ru_maxrss of the runner process (its test's processes "
        "stay at a few MB)."
    )
    for failure in failures:
        section.notes.append(f"**Failed: {failure}.**")
    return section
