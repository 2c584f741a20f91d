"""12. Namespace mode: what a test in namespaces of its own costs, against domain mode and upstream.

``--isolation namespace`` starts the test in new user, network, mount and IPC namespaces
(loopback brought up, a tmpfs on /dev/shm): a fork and a few system calls where domain
mode makes one ``posix_spawn``, plus the kernel's work to make and tear down the
namespaces. ``auto`` first probes once whether namespaces are allowed (a second set-up
in a child that exits at once). A no-op test (``true``) through our RUNNER in each mode
and through Jazzy's upstream, interleaved (ABBA), medians. Then the case namespace mode
is for: the pool's only ID held elsewhere, where domain mode waits and namespace mode
runs at once.
"""

from __future__ import annotations

import subprocess
from collections import defaultdict
from pathlib import Path

from common import (
    LABELS,
    OURS,
    UPSTREAM,
    Context,
    Section,
    at_most,
    interleaved,
    median,
    ms,
    progress,
    ratio,
    run_timed,
    verdict,
)

NOOP = ("true",)
#: What namespace mode may add to a test over domain mode (the issue's target).
ADDED_TARGET = 0.010
ISOLATION = "ROS_ISOLATED_TEST_ISOLATION"
#: The columns: ours in each mode (the same RUNNER, the variable set), and Jazzy's upstream.
MODES = ("domain", "namespace", "auto")
COLUMNS = (*(f"ours-{mode}" for mode in MODES), UPSTREAM)
HEADINGS = {
    **{f"ours-{mode}": f"ours, isolation {mode}" for mode in MODES},
    UPSTREAM: LABELS[UPSTREAM],
}


def _command(ctx: Context, column: str, result: Path) -> list[str]:
    runner = UPSTREAM if column == UPSTREAM else OURS
    return ctx.runner_command(runner, result, NOOP)


def _env(ctx: Context, column: str, **extra: str) -> dict[str, str]:
    if column == UPSTREAM:
        return ctx.environment(UPSTREAM, **extra)
    return ctx.environment(OURS, **{ISOLATION: column.removeprefix("ours-"), **extra})


def _refused(ctx: Context) -> str | None:
    """Why namespace mode cannot run here (its one error line), or None when it runs."""
    scratch = ctx.scratch("namespace_mode")
    proc = subprocess.run(
        _command(ctx, "ours-namespace", scratch / "check.xml"),
        env=_env(ctx, "ours-namespace"),
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    if proc.returncode == 0:
        return None
    return (proc.stderr.strip().splitlines() or [f"exit {proc.returncode}"])[-1]


def _pool_held_elsewhere(ctx: Context, reps: int) -> tuple[list[float], str]:
    """Namespace mode's no-op wall times while the pool's one ID is held by another runner.

    The holder is a real reservation in this process (same lock directory); the runs
    must all say the ID is not reserved and never wait.
    """
    from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator

    scratch = ctx.scratch("namespace_mode")
    lock_dir = Path(ctx.environment(OURS)["ROS_ISOLATED_TEST_LOCK_DIR"]) / "held-elsewhere"
    coordinator = DomainCoordinator(lock_dir, range(1, 102))
    walls: list[float] = []
    said = "not measured"
    with coordinator.reserve(["benches/namespace_mode.py", "holder"]) as held:
        pool = str(held.domain_id)
        env = _env(
            ctx,
            "ours-namespace",
            ROS_ISOLATED_TEST_DOMAINS=pool,
            ROS_ISOLATED_TEST_LOCK_DIR=str(lock_dir),
        )
        for _ in range(reps):
            result = scratch / "held.xml"
            result.unlink(missing_ok=True)
            walls.append(run_timed(_command(ctx, "ours-namespace", result), env).seconds)
        text = result.read_text(encoding="utf-8") if result.is_file() else ""
        if 'name="ros_domain_id_reserved" value="no' in text:
            said = f"ran at once on ID {pool}, unreserved (its result file says so)"
        else:
            said = "**did not say it ran unreserved**"
    return walls, said


def run(ctx: Context) -> Section:
    """Time the no-op test through ours in each mode and through Jazzy's upstream."""
    reps = 5 if ctx.quick else 31
    section = Section(
        f"12. Namespace mode: a no-op test (`true`) through our RUNNER in each isolation mode "
        f"and through Jazzy's upstream, {reps} runs each, interleaved",
        ("", *(HEADINGS[column] for column in COLUMNS), "target"),
    )
    why = _refused(ctx)
    if why is not None:
        section.notes.append(f"Namespace mode not measured: it is refused here: `{why}`.")
        return section
    progress(f"namespace_mode: warming up, then {reps} interleaved no-op runs per mode")
    scratch = ctx.scratch("namespace_mode")
    for column in COLUMNS:
        run_timed(_command(ctx, column, scratch / f"warm-{column}.xml"), _env(ctx, column))
    walls: dict[str, list[float]] = defaultdict(list)
    failures: dict[str, int] = defaultdict(int)
    for _, column in interleaved(reps, COLUMNS):
        result = scratch / f"{column}.xml"
        result.unlink(missing_ok=True)
        outcome = run_timed(_command(ctx, column, result), _env(ctx, column))
        walls[column].append(outcome.seconds)
        if outcome.returncode != 0 or not result.is_file():
            failures[column] += 1
    wall = {column: median(walls[column]) for column in COLUMNS}
    added = {column: wall[column] - wall["ours-domain"] for column in COLUMNS}
    section.rows.append(("wall time per test (median)", *(ms(wall[c]) for c in COLUMNS), ""))
    target = verdict(at_most(added["ours-namespace"], ADDED_TARGET))
    section.rows.append(
        (
            "added over ours in domain mode",
            *("" if c in ("ours-domain", UPSTREAM) else ms(added[c]) for c in COLUMNS),
            f"namespace ≤ {ADDED_TARGET * 1000:.0f} ms: {target}",
        )
    )
    section.rows.append(
        (
            "ours / Jazzy upstream",
            *("" if c == UPSTREAM else ratio(wall[c], wall[UPSTREAM]) for c in COLUMNS),
            "",
        )
    )
    progress("namespace_mode: the pool's one ID held elsewhere")
    held_walls, said = _pool_held_elsewhere(ctx, max(3, reps // 3))
    section.rows.append(
        (
            "the pool's only ID held by another runner: wall per test (median)",
            "waits until it is released",
            f"{ms(median(held_walls))}: {said}",
            "as namespace (namespaces are allowed here)",
            "-",
            "",
        )
    )
    section.notes.append(
        "Each column is the same RUNNER script started as ctest starts it, "
        f"`{ISOLATION}` set to the mode (upstream: Jazzy's `run_test_isolated.py`). "
        "Namespace mode forks and enters new user, network, mount and IPC namespaces "
        "(loopback up, a tmpfs on /dev/shm) where domain mode calls `posix_spawn` once; "
        "`auto` also probes once per run whether namespaces are allowed (a child that "
        "makes them and exits), so it pays the set-up twice. The kernel's teardown of a "
        "network namespace runs after the test, asynchronously."
    )
    for column, count in failures.items():
        if count:
            section.notes.append(f"**{count} runs of {HEADINGS[column]} failed.**")
    return section
