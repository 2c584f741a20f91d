"""5. Suite throughput: the example package's real rclpy tests under ``ctest -jN``.

The six crosstalk_demo tests (each publishes a token over Fast DDS for a few seconds and
fails on hearing anyone else's) are built once per runner with
``examples/crosstalk_workspace.py`` (CROSSTALK_RUNNER=isolated or upstream) and run by
ctest exactly as colcon would, but without colcon's own start-up in the measurement.
Isolation should cost nothing visible here: the tests' own seconds dominate.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from common import (
    OURS,
    REPO,
    RUNNERS,
    UPSTREAM,
    Context,
    Section,
    interleaved,
    median,
    progress,
    ratio,
    secs,
    timed_ctest,
)

sys.path.insert(0, str(REPO / "examples"))
import crosstalk_workspace

JOBS = (1, 2, 6)
QUICK_JOBS = (6,)
#: CROSSTALK_RUNNER value for each of our runner names.
CROSSTALK = {OURS: "isolated", UPSTREAM: "upstream"}
TARGET = 1.02
_SUMMARY = re.compile(r"(\d+)% tests passed, (\d+) tests? failed out of (\d+)")


def _ctest(ctx: Context, build_dir: Path, jobs: int) -> tuple[float, int, int]:
    """Run the package's tests with ``ctest -jN``: wall seconds, passed, total."""
    env = ctx.environment()
    colcon = crosstalk_workspace.colcon_env()  # the venv's bin/ and prefix first, as colcon
    env["PATH"] = colcon["PATH"]
    env["CMAKE_PREFIX_PATH"] = colcon["CMAKE_PREFIX_PATH"]
    wall, output = timed_ctest(build_dir, jobs, env)
    match = _SUMMARY.search(output)
    if match is None:
        return wall, 0, 0
    total = int(match[3])
    return wall, total - int(match[2]), total


def run(ctx: Context) -> Section:
    """Build once per runner, then interleaved ``ctest -jN`` runs for each N."""
    reps = 1 if ctx.quick else 3
    jobs_run = QUICK_JOBS if ctx.quick else JOBS
    workspace = ctx.scratch("suite")
    build_dirs: dict[str, Path] = {}
    baked: dict[str, str] = {}
    for runner in RUNNERS:
        progress(f"suite: colcon build with CROSSTALK_RUNNER={CROSSTALK[runner]}")
        base = crosstalk_workspace.build(workspace, CROSSTALK[runner])
        baked[runner], _ = crosstalk_workspace.registered_tests(base)
        build_dirs[runner] = base / "build" / crosstalk_workspace.PACKAGE
    walls: dict[tuple[str, int], list[float]] = {}
    passed: dict[tuple[str, int], list[tuple[int, int]]] = {}
    for jobs in jobs_run:
        for rep, runner in interleaved(reps):
            progress(f"suite: ctest -j{jobs} through {runner} ({rep + 1}/{reps})")
            wall, ok, total = _ctest(ctx, build_dirs[runner], jobs)
            walls.setdefault((runner, jobs), []).append(wall)
            passed.setdefault((runner, jobs), []).append((ok, total))
    section = Section(
        f"5. Suite throughput: crosstalk_demo's 6 rclpy tests under ctest -jN, "
        f"{reps} run(s) each, interleaved",
        ("ctest", "ours: wall", "upstream: wall", "ours / upstream", "passed: ours",
         "passed: upstream"),
    )  # fmt: skip
    for jobs in JOBS:
        if jobs not in jobs_run:
            section.rows.append((f"-j{jobs}", "skipped in --quick", "", "", "", ""))
            continue
        ours, up = median(walls[(OURS, jobs)]), median(walls[(UPSTREAM, jobs)])
        counts = {
            runner: f"{sum(ok for ok, _ in passed[(runner, jobs)])} of "
            f"{sum(total for _, total in passed[(runner, jobs)])}"
            for runner in RUNNERS
        }
        section.rows.append(
            (f"-j{jobs}", secs(ours), secs(up), ratio(ours, up), counts[OURS], counts[UPSTREAM])
        )
    section.notes.append(
        f"Target: ours / upstream at most {TARGET:.2f}. Runners as baked into "
        f"CTestTestfile.cmake: ours `{baked[OURS]}`, upstream `{baked[UPSTREAM]}`; both "
        f"run by `{sys.executable} -u`."
    )
    return section
