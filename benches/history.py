"""16. The test history at scale: recording a run of 10,000 tests, reading 200 x 10,000.

- *recording*: a run of 10,000 tests (a tree as the runner leaves it, made by
  tests/helpers/result_tree.py: 10,000 result files) recorded by ``history record``
  (wall, peak RSS, in a process of its own: tests/helpers/peak_rss), beside ``report``
  over the same tree; and the database write alone (the run already read, timed in this
  process), which is what recording adds where the tree is read once anyway (the colcon
  extension's page, ``run``'s own result file).
- *reading*: a database of 200 runs of 10,000 tests (2 million attempts; written in this
  process from made-up runs, a fiftieth failing, a fortieth flaky) read by ``history
  --json`` over the default window (20 runs) and over all 200, and by ``history
  durations``; against re-reading the result trees instead: ``report`` over one tree of
  10,000 tests, times 200 (one tree measured, the rest extrapolated: 2 million result
  files do not fit a CI machine's disk).

Targets (the issue's): recording adds under 5% to ``report`` over the same tree;
``history`` answers in under a second for 200 x 10,000. ``--quick``: 1,000 tests and 20
runs, a few seconds. Ours only: no other tool keeps this history.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from common import REPO, Context, Section, median, progress, secs

sys.path.insert(0, str(REPO / "tests"))
from helpers import peak_rss, result_tree  # the tests' helpers, shared

from ros_isolated_test.history import record, store

CLI = str(Path(sys.executable).parent / "ros-isolated-test")
#: (tests per run, runs) of the full size and of --quick.
FULL = (10_000, 200)
QUICK = (1_000, 20)
RECORD_SHARE = 0.05
ANSWER_SECONDS = 1.0


def _measure(argv: list[str], env: dict[str, str], reps: int) -> tuple[float, float]:
    """Median wall seconds and the largest peak RSS (MiB) of ``argv`` over ``reps`` runs."""
    found = [peak_rss.measure(argv, env=env) for _ in range(reps)]
    for item in found:
        if item.returncode not in (0, 1):
            raise RuntimeError(f"{argv[:3]} exited {item.returncode}")
    return median([item.wall for item in found]), max(item.max_rss for item in found) / 2**20


def _made_up_run(tests: int, number: int) -> record.Run:
    """Run ``number`` of ``tests`` tests: a fiftieth failing, a fortieth passing on a rerun."""
    run = record.Run()
    started = f"2026-01-01T00:00:00+00:00#{number:04d}"
    for k in range(tests):
        name = f"pkg_{k % 20:03d}/test_{k:05d}"
        seconds = 0.2 + (k * 7919 % 3000) / 1000
        if k % 50 == 49 and (k + number) % 3:
            rows: list[record.AttemptRow] = [("failed", seconds, 1 + k % 8, "expected 10, got 9")]
        elif k % 40 == 39 and (k + number) % 2:
            rows = [("failed", seconds, 1 + k % 8, "timeout"), ("passed", seconds, 2, "")]
        else:
            rows = [("passed", seconds, 1 + k % 8, "")]
        run.tests[name] = rows
        run.starts[name] = started
    return run


def _share(part: float, whole: float) -> str:
    return f"{part / whole:.1%}" if whole else "-"


def run(ctx: Context) -> Section:
    """Record one run, read a full database; times and memory against re-reading trees."""
    tests, runs = QUICK if ctx.quick else FULL
    reps = 1 if ctx.quick else 3
    scratch = ctx.scratch("history")
    env = ctx.environment()
    section = Section(
        f"16. The test history at scale: {tests:,} tests, {runs} runs (median of {reps})",
        ("what", "wall", "peak RSS", "against", "target"),
    )

    report_wall = _recording(scratch, env, tests, reps, section)
    _reading(scratch, env, tests, runs, reps, report_wall, section)
    section.notes.append(
        "Re-reading the trees is `report` over one tree times the runs (one measured, the "
        "rest extrapolated). Recording as a separate command reads the tree again, so it "
        "costs about what `report` does; the target is the write, what recording adds "
        "where the run is read once anyway."
    )
    return section


def _recording(
    scratch: Path, env: dict[str, str], tests: int, reps: int, section: Section
) -> float:
    """One run's tree: ``report``, ``history record`` and the write alone; report's wall."""
    progress(f"history: a tree of {tests:,} tests")
    tree = scratch / "tree"
    result_tree.write_tree(tree, tests, 1)
    report_wall, report_rss = _measure([CLI, "report", str(tree)], env, reps)
    section.rows.append(
        (f"`report` over one run's tree ({tests:,} tests)", secs(report_wall),
         f"{report_rss:.0f} MiB", "", "")
    )  # fmt: skip

    progress("history: history record")
    record_walls = []
    record_rss = 0.0
    for k in range(reps):
        db = scratch / f"record-{k}.sqlite3"
        wall, rss = _measure([CLI, "history", "record", "--db", str(db), str(tree)], env, 1)
        record_walls.append(wall)
        record_rss = max(record_rss, rss)
    with store.connect(db, write=False) as check:
        recorded = check.execute("SELECT count(*) FROM attempts").fetchone()[0]
    check.close()
    if recorded < tests:
        raise RuntimeError(f"history record kept {recorded} attempts of {tests} tests")
    record_wall = median(record_walls)
    section.rows.append(
        ("`history record` of that tree (reads it again, then writes)", secs(record_wall),
         f"{record_rss:.0f} MiB", f"{_share(record_wall, report_wall)} of `report`", "")
    )  # fmt: skip

    progress("history: the write alone")
    gathered = record.gathered([tree])
    writes = []
    for k in range(reps):
        connection = store.connect(scratch / f"write-{k}.sqlite3")
        start = time.perf_counter()
        record.write(connection, gathered)
        writes.append(time.perf_counter() - start)
        connection.close()
    write = median(writes)
    met = write / report_wall < RECORD_SHARE
    section.rows.append(
        ("the database write alone (the run read once, for `report` or the page)", secs(write),
         "", f"{_share(write, report_wall)} of `report`",
         f"< {RECORD_SHARE:.0%} of `report`: {'met' if met else '**NOT met**'}")
    )  # fmt: skip

    return report_wall


def _reading(
    scratch: Path,
    env: dict[str, str],
    tests: int,
    runs: int,
    reps: int,
    report_wall: float,
    section: Section,
) -> None:
    """A database of ``runs`` x ``tests`` read by ``history``, against re-reading trees."""
    progress(f"history: a database of {runs} runs x {tests:,} tests")
    full = scratch / "full.sqlite3"
    connection = store.connect(full)
    start = time.perf_counter()
    for number in range(runs):
        record.write(connection, _made_up_run(tests, number))
    built = time.perf_counter() - start
    connection.close()
    size = full.stat().st_size / 2**20
    section.notes.append(
        f"The database of {runs} x {tests:,} ({runs * tests:,} runs of a test) took "
        f"{secs(built)} to write ({secs(built / runs)} a run) and is {size:.0f} MiB."
    )
    rereading = report_wall * runs
    for label, argv in (
        ("`history --json` (the last 20 runs)", ["--json"]),
        (f"`history --json --runs {runs}` (every run)", ["--json", "--runs", str(runs)]),
        ("`history durations FILE` (the last 20 runs)", ["durations", str(scratch / "d.json")]),
    ):
        progress(f"history: {label}")
        command = [CLI, "history", *argv[:1], "--db", str(full), *argv[1:]]
        wall, rss = _measure(command, env, reps)
        met = wall < ANSWER_SECONDS
        section.rows.append(
            (label, secs(wall), f"{rss:.0f} MiB",
             f"re-reading {runs} trees: {secs(rereading)} (extrapolated)",
             f"< {ANSWER_SECONDS:g} s: {'met' if met else '**NOT met**'}")
        )  # fmt: skip
