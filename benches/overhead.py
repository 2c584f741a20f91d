"""1. Per-test overhead: what wrapping a test that does nothing costs, ours against upstream.

Every ctest test pays this once, so it is the floor of any suite's cost. The wall time
is split into interpreter start-up (an interpreter in the same venv that starts and
exits at once, ``os._exit``: what no runner can avoid) and the runner's own work; an
in-process timer shows imports and the run itself, and ``-X importtime`` names the
imports that cost the most. The no-op runs are taken on a quiet host and again with
3000 idle processes alive (``idle_scene``): a runner that reads every process's
environment pays for them on every test.
"""

from __future__ import annotations

import subprocess
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import idle_scene
from common import (
    KILTED,
    LABELS,
    OURS,
    RUNNERS,
    UPSTREAM,
    Context,
    Section,
    at_most,
    interleaved,
    median,
    ms,
    parse_importtime,
    progress,
    quotient,
    ratio,
    run_timed,
    verdict,
)
from idle_scene import BUSY, QUIET

NOOP = ("true",)
#: Own work (runner wall minus interpreter start-up) the issue allows us.
OWN_WORK_TARGET = 0.020
#: Own work against upstream's own work, in the same run (issue 44: a quarter).
OWN_WORK_RATIO = 0.25
#: Wall time with the idle processes alive over quiet wall time the issue allows us.
BUSY_TARGET = 1.10

#: Runs a runner script by path after importing what it imports, timing both parts.
_PROBE = r"""
import os, runpy, sys, time
kind, script, timing = sys.argv[1:4]
# Before the imports: ament_cmake_test.main's default argv is bound when it is imported.
sys.argv = [script, *sys.argv[4:]]
t0 = time.perf_counter()
if kind == "ours":
    import ros_isolated_test.ament.args
else:
    import ament_cmake_test, domain_coordinator
t1 = time.perf_counter()
code = 0
real_exit = os._exit


def _exit(status):
    # Our script ends with os._exit (no teardown): a SystemExit here, so the timer can
    # write first; the probe then ends as the script would.
    raise SystemExit(status)


os._exit = _exit
try:
    runpy.run_path(script, run_name="__main__")
except SystemExit as stop:
    code = stop.code
t2 = time.perf_counter()
with open(timing, "w") as handle:
    handle.write(f"{t1 - t0} {t2 - t1}")
if kind == "ours":
    sys.stdout.flush()
    real_exit(code if isinstance(code, int) else 1)
sys.exit(code)
"""


@dataclass(frozen=True)
class ImportEdge:
    """A module outside ros_isolated_test, and the module (ours or the script) importing it."""

    module: str
    importer: str


@dataclass(frozen=True)
class ImportProfile:
    """Our runner's imports: outside modules by first importer, our own modules, the total."""

    outside: list[tuple[ImportEdge, float]]
    own: list[tuple[str, float]]
    own_total: float
    total: float


def import_profile(ctx: Context, reps: int) -> ImportProfile:
    """Where our runner's import time goes, from ``-X importtime`` of a real no-op run.

    Outside modules are those ros_isolated_test (or the runner script) pulls in from
    elsewhere, with their cumulative time, under the module that imported them first;
    our own modules are shown with their self time. Medians over ``reps`` runs. Modules
    the interpreter already loads at start-up (``python -c pass``) are left out: every
    Python process pays for them.
    """
    startup = subprocess.run(
        [ctx.python, "-X", "importtime", "-c", "pass"],
        env=ctx.environment(),
        capture_output=True,
        text=True,
        check=False,
    )
    preloaded = {name for _, name, _, _ in parse_importtime(startup.stderr.splitlines())}
    edges: dict[ImportEdge, list[float]] = defaultdict(list)
    own: dict[str, list[float]] = defaultdict(list)
    own_totals: list[float] = []
    totals: list[float] = []
    result = ctx.scratch("overhead") / "importtime.xml"
    for _ in range(reps):
        proc = subprocess.run(
            [ctx.python, "-X", "importtime", *ctx.runner_command(OURS, result, NOOP)[1:]],
            env=ctx.environment(),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            check=False,
        )
        entries = [e for e in parse_importtime(proc.stderr.splitlines()) if e[1] not in preloaded]
        # -X importtime prints children before their parent: walk backwards with a stack.
        stack: list[tuple[int, str]] = []
        own_us = 0
        total_us = 0
        for level, name, self_us, cumulative in reversed(entries):
            while stack and stack[-1][0] >= level:
                stack.pop()
            importer = stack[-1][1] if stack else "the runner script (or a lazy import)"
            stack.append((level, name))
            if level == 0:
                total_us += cumulative
            if name.startswith("ros_isolated_test"):
                own_us += self_us
                own[name].append(self_us / 1e6)
            elif importer.startswith("ros_isolated_test") or level == 0:
                edges[ImportEdge(name, importer)].append(cumulative / 1e6)
        own_totals.append(own_us / 1e6)
        totals.append(total_us / 1e6)
    return ImportProfile(
        outside=sorted(
            ((edge, median(times)) for edge, times in edges.items()), key=lambda item: -item[1]
        ),
        own=sorted(((name, median(times)) for name, times in own.items()), key=lambda i: -i[1]),
        own_total=median(own_totals),
        total=median(totals),
    )


def _probe(ctx: Context, runner: str, timing: Path) -> tuple[float, float, float] | None:
    """One no-op run under the in-process timer: (imports, run, whole process wall)."""
    result = ctx.scratch("overhead") / f"probe-{runner}.xml"
    command = ctx.runner_command(runner, result, NOOP)
    probe = [ctx.python, "-u", "-c", _PROBE, runner, command[2], str(timing), *command[3:]]
    outcome = run_timed(probe, ctx.environment())
    if outcome.returncode != 0:
        return None
    imports, rest = (float(part) for part in timing.read_text().split())
    return imports, rest, outcome.seconds


def _timed_noops(
    ctx: Context, runners: tuple[str, ...], reps: int, scene: str, into: _Walls
) -> None:
    """``reps`` interleaved no-op runs of each runner, and each venv's bare start-up."""
    scratch = ctx.scratch("overhead")
    for _, runner in interleaved(reps, runners):
        result = scratch / f"{runner}.xml"
        result.unlink(missing_ok=True)
        env = ctx.environment(runner)
        outcome = run_timed(ctx.runner_command(runner, result, NOOP), env)
        into.walls[scene, runner].append(outcome.seconds)
        if outcome.returncode != 0 or not result.is_file():
            into.failures[scene, runner] += 1
        if runner in (UPSTREAM, KILTED):  # the floor of this pair's interpreter
            bare = [ctx.python_of(runner), "-u", "-c", "import os; os._exit(0)"]
            into.startups[scene, runner].append(run_timed(bare, env).seconds)


class _Walls:
    """Wall times, bare start-ups and failures, by (scene, runner)."""

    def __init__(self) -> None:
        self.walls: dict[tuple[str, str], list[float]] = defaultdict(list)
        self.startups: dict[tuple[str, str], list[float]] = defaultdict(list)
        self.failures: dict[tuple[str, str], int] = defaultdict(int)

    def wall(self, scene: str, runner: str) -> float:
        return median(self.walls[scene, runner])

    def startup(self, scene: str, runner: str) -> float:
        upstream = UPSTREAM if runner in (OURS, UPSTREAM) else KILTED
        return median(self.startups[scene, upstream])


def run(ctx: Context) -> Section:
    """Time the no-op test through each runner, quiet and busy, interleaved; split ours."""
    reps = 5 if ctx.quick else 31
    probe_reps = 3 if ctx.quick else 11
    runners = ctx.all_runners()
    scratch = ctx.scratch("overhead")
    progress(f"overhead: warming up, then {reps} interleaved no-op runs per runner and scene")
    for runner in runners:  # warm-up: bytecode caches and the page cache
        warm = scratch / f"warm-{runner}.xml"
        run_timed(ctx.runner_command(runner, warm, NOOP), ctx.environment(runner))
    walls = _Walls()
    scene_note = idle_scene.in_scenes(
        ctx.python,
        ctx.work,
        reps,
        lambda scene, n: _timed_noops(ctx, runners, n, scene, walls),
    )
    # Start and exit, no teardown: ours skips it too (os._exit once all is written), so
    # the floor is the bare start; upstream's teardown counts as its own work.
    parts: dict[str, tuple[list[float], list[float], list[float]]] = {
        runner: ([], [], []) for runner in RUNNERS
    }
    for _, runner in interleaved(probe_reps):
        measured = _probe(ctx, runner, scratch / f"timing-{runner}.txt")
        if measured is not None:
            for index, value in enumerate(measured):
                parts[runner][index].append(value)
    progress("overhead: import profile of ours (-X importtime)")
    profile = import_profile(ctx, 3)

    pairs, section = ctx.pair_section(
        f"1. Per-test overhead: a no-op test (`true`, --generate-result-on-success), "
        f"{reps} runs each per scene, interleaved",
    )

    def row(
        label: str,
        cell: Callable[[str], str],
        pair_ratio: Callable[[str, str], str],
        target: str = "",
    ) -> None:
        cells = [label]
        for ours, upstream in pairs:
            cells += [cell(ours), cell(upstream), pair_ratio(ours, upstream)]
        section.rows.append((*cells, target))

    def wall_ratio(scene: str) -> Callable[[str, str], str]:
        return lambda o, u: ratio(walls.wall(scene, o), walls.wall(scene, u))

    def pair_target(scene: str) -> str:
        states = [
            f"{verdict(at_most(quotient(walls.wall(scene, o), walls.wall(scene, u)), 1.0))} "
            f"({LABELS[u].split()[0]})"
            for o, u in pairs
        ]
        return "ours / upstream ≤ 1.00: " + ", ".join(states)

    busy_quiet = {r: quotient(walls.wall(BUSY, r), walls.wall(QUIET, r)) for r in runners}
    row(
        "wall time per test, quiet (median)",
        lambda r: ms(walls.wall(QUIET, r)),
        wall_ratio(QUIET),
        pair_target(QUIET),
    )
    row(
        f"wall time per test, {idle_scene.IDLE_PROCESSES} idle processes alive (median)",
        lambda r: ms(walls.wall(BUSY, r)),
        wall_ratio(BUSY),
        pair_target(BUSY),
    )
    ours_busy = [verdict(at_most(busy_quiet[o], BUSY_TARGET)) for o, _ in pairs]
    row(
        "busy / quiet",
        lambda r: ratio(busy_quiet[r], 1.0),
        lambda o, u: "",
        f"ours ≤ {BUSY_TARGET:.2f}: " + ", ".join(ours_busy),
    )
    row(
        "interpreter start-up (`python -u -c 'import os; os._exit(0)'`), quiet",
        lambda r: ms(walls.startup(QUIET, r)),
        lambda o, u: "",
    )
    own = {r: walls.wall(QUIET, r) - walls.startup(QUIET, r) for r in runners}
    own_state = [verdict(at_most(own[o], OWN_WORK_TARGET)) for o, _ in pairs]
    own_ratio_state = [
        f"{verdict(at_most(quotient(own[o], own[u]), OWN_WORK_RATIO))} ({LABELS[u].split()[0]})"
        for o, u in pairs
    ]
    row(
        "the runner's own work (wall - start-up), quiet",
        lambda r: ms(own[r]),
        lambda o, u: ratio(own[o], own[u]),
        f"ours / upstream ≤ {OWN_WORK_RATIO:.2f}: "
        + ", ".join(own_ratio_state)
        + f"; ours < {OWN_WORK_TARGET * 1000:.0f} ms: "
        + ", ".join(own_state),
    )

    def probe_cell(index: int) -> Callable[[str], str]:
        return lambda r: ms(median(parts[r][index])) if r in parts else "-"

    def probe_ratio(index: int) -> Callable[[str, str], str]:
        return lambda o, u: (
            ratio(median(parts[o][index]), median(parts[u][index])) if u in parts else ""
        )

    row(f"probe, in-process timer: imports (median of {probe_reps})", probe_cell(0), probe_ratio(0))
    row("probe, in-process timer: the run (arguments, domain ID, `true`, result file)",
        probe_cell(1), probe_ratio(1))  # fmt: skip
    section.notes.append(
        "The two in-process rows come from separate probe runs (the script loaded through "
        "runpy, which compiles it, inside a timer), so they need not add up to the row "
        "above them: the wall times are the measure, the probes show where time goes. "
        "They are taken for the Jazzy pair only."
    )
    section.notes.append(
        f"Busy host: {scene_note}. Order: quiet, busy, quiet (half of the quiet runs on "
        "each side); within each, the runners interleaved (ABBA)."
    )
    for (scene, runner), count in walls.failures.items():
        if count:
            section.notes.append(f"**{count} {LABELS[runner]} runs failed ({scene}).**")
    for runner, why in ctx.missing.items():
        section.notes.append(f"{LABELS[runner]}: not measured: {why}.")
    if profile.outside:
        outside = ", ".join(
            f"{edge.module} {seconds * 1000:.0f} ms (first imported by {edge.importer})"
            for edge, seconds in profile.outside[:8]
        )
        own_modules = ", ".join(
            f"{name.removeprefix('ros_isolated_test.')} {seconds * 1000:.1f} ms"
            for name, seconds in profile.own[:5]
        )
        section.notes.append(
            f"Where our imports go (`-X importtime` of a no-op run, median of 3; the profiler "
            f"inflates every figure; modules `python -c pass` already loads left out): "
            f"{profile.total * 1000:.0f} ms in all. Heaviest imports from outside "
            f"ros_isolated_test, with all they pull in: {outside}. ros_isolated_test's own "
            f"modules, {profile.own_total * 1000:.0f} ms of self time, most in: {own_modules}."
        )
    return section
