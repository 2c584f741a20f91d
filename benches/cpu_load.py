"""9. CPU load: a timing-sensitive suite under ``ctest -j`` beyond the core count.

Many CI suites have tests that are as much about time as about results: a control loop
that must keep its period, a test that waits a fixed time for a message. Run more of them
at once than there are CPUs and they share the CPUs, run slower than they would alone
and fail, although nothing is wrong with the code: the flaky tests a domain ID cannot
fix. ros-isolated-test can hold CPUs like domain IDs: with
``ROS_ISOLATED_TEST_RESOURCES=cpu=1`` per test and the capacity at the machine's CPUs,
at most that many of them run at once, whatever ``-j`` says, and the rest queue.

A generated CMake project (plain ``add_test``, no ROS needed) registers N tests, each
our RUNNER around a Python loop that does a fixed amount of CPU work and fails when its
wall time is more than :data:`STRETCH_LIMIT` x its own CPU time (the time it takes
alone on an idle CPU): a real-time deadline, scaled to the machine. The same project is
built twice, without a request and with ``--env ROS_ISOLATED_TEST_RESOURCES=cpu=1`` on
every test (what ``ament_add_test(... ENV ...)`` passes), and each runs under
``ctest -jJ``, J = 4 x the CPUs, interleaved. Only ours is run: upstream has no resource
control, so it behaves as ours without a request.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from common import OURS, Context, Section, median, progress, secs, timed_ctest, verdict

#: A test fails when its wall time exceeds this many times its own CPU time.
STRETCH_LIMIT = 2.0
#: How many tests the suite has and how long each works alone, per mode.
FULL = (16, 1.0)
QUICK = (6, 0.3)
#: ctest's own timeout per test: only stops a hang (a queued test waits its turn in it).
CTEST_TIMEOUT = 600
VARIANTS = ("no request", "cpu=1 per test")
_SUMMARY = re.compile(r"(\d+)% tests passed, (\d+) tests? failed out of (\d+)")

#: The test: argv is the loop count, the stretch limit and the log to append one line to.
LOOP = """
import os, sys, time
count, limit, log = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
wall, cpu = time.perf_counter(), time.process_time()
total = 0
for i in range(count):
    total += i * i % 7
wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
os.write(fd, f"{wall:.6f} {cpu:.6f}\\n".encode())
os.close(fd)
if wall > limit * cpu:
    sys.exit(f"deadline missed: {wall:.3f} s wall for {cpu:.3f} s of CPU (limit {limit:g}x)")
"""

CMAKE_HEAD = """\
cmake_minimum_required(VERSION 3.16)
project(cpu_load NONE)
enable_testing()
"""
CMAKE_TEST = """\
add_test(NAME t{index} COMMAND [==[{python}]==] -u [==[{runner}]==] [==[{result}]==]
  --package-name bench --generate-result-on-success {env}--command
  [==[{python}]==] -c [==[{loop}]==] {count} {limit} [==[{log}]==])
set_tests_properties(t{index} PROPERTIES TIMEOUT {timeout})
"""


@dataclass
class Round:
    """One ``ctest -j`` run of the suite."""

    wall: float
    failed: int
    total: int
    missed: int
    stretches: list[float]


def _cpus() -> int:
    """The CPUs this process may use: the capacity a runner defaults to, set explicitly."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _calibrate(python: str, seconds: float) -> int:
    """The loop count that takes about ``seconds`` of CPU on this machine."""
    probe = 2_000_000
    code = (
        "import time\nt = time.process_time()\ntotal = 0\n"
        f"for i in range({probe}):\n    total += i * i % 7\n"
        "print(time.process_time() - t)"
    )
    took = min(
        float(subprocess.run([python, "-c", code], capture_output=True, text=True,
                             check=True).stdout)
        for _ in range(3)
    )  # fmt: skip
    return max(1000, int(probe * seconds / max(took, 1e-6)))


def _project(ctx: Context, folder: Path, tests: int, count: int, request: str) -> Path:
    """Configure the suite in ``folder``: its build directory, ready for ctest."""
    source, build, results = folder / "src", folder / "build", folder / "results"
    for path in (source, build, results):
        path.mkdir(parents=True, exist_ok=True)
    env = f"--env [==[ROS_ISOLATED_TEST_RESOURCES={request}]==] " if request else ""
    lines = [CMAKE_HEAD]
    for index in range(tests):
        lines.append(
            CMAKE_TEST.format(
                index=index,
                python=ctx.python_of(OURS),
                runner=ctx.runners[OURS],
                result=results / f"t{index}.xml",
                env=env,
                loop=LOOP,
                count=count,
                limit=STRETCH_LIMIT,
                log=folder / "times.log",
                timeout=CTEST_TIMEOUT,
            )
        )
    (source / "CMakeLists.txt").write_text("".join(lines))
    subprocess.run(
        ["cmake", "-S", str(source), "-B", str(build)],
        capture_output=True,
        check=True,
        env=ctx.environment(OURS),
    )
    return build


def _round(ctx: Context, build: Path, jobs: int, cpus: int) -> Round:
    """``ctest -jJ`` once: wall time, failures, and each test's wall / CPU."""
    log = build.parent / "times.log"
    log.unlink(missing_ok=True)
    env = ctx.environment(OURS, ROS_ISOLATED_TEST_CAPACITY=f"cpu={cpus}")
    env.pop("ROS_ISOLATED_TEST_RESOURCES", None)
    wall, output = timed_ctest(build, jobs, env)
    stretches = []
    if log.exists():
        for line in log.read_text().splitlines():
            took, cpu = map(float, line.split())
            stretches.append(took / cpu if cpu > 0 else float("inf"))
    match = _SUMMARY.search(output)
    total = int(match[3]) if match else 0
    failed = int(match[2]) if match else 0
    missed = sum(stretch > STRETCH_LIMIT for stretch in stretches)
    return Round(wall, failed, total, missed, stretches)


def run(ctx: Context) -> Section:
    """Both variants of the suite, interleaved: failures, deadlines missed, wall time."""
    tests, work = QUICK if ctx.quick else FULL
    reps = 1 if ctx.quick else 3
    cpus = _cpus()
    jobs = min(tests, 4 * cpus)
    progress(f"cpu_load: calibrating a loop of {work:g} s of CPU")
    count = _calibrate(ctx.python_of(OURS), work)
    builds = {
        variant: _project(ctx, ctx.scratch(f"cpu_load/{index}"), tests, count,
                          "cpu=1" if index else "")
        for index, variant in enumerate(VARIANTS)
    }  # fmt: skip
    rounds: dict[str, list[Round]] = {variant: [] for variant in VARIANTS}
    for rep in range(reps):
        order = VARIANTS if rep % 2 == 0 else tuple(reversed(VARIANTS))
        for variant in order:
            progress(f"cpu_load: ctest -j{jobs}, {variant} ({rep + 1}/{reps})")
            rounds[variant].append(_round(ctx, builds[variant], jobs, cpus))
    section = Section(
        f"9. CPU load: {tests} timing-sensitive tests ({work:g} s of CPU each, deadline "
        f"{STRETCH_LIMIT:g}x) under ctest -j{jobs} on {cpus} CPUs, {reps} run(s) each",
        ("", *VARIANTS),
    )
    ideal = tests * work / cpus

    def total(variant: str, field: str) -> str:
        runs = rounds[variant]
        return f"{sum(getattr(r, field) for r in runs)} of {sum(r.total for r in runs)}"

    def stretch(variant: str, pct: str) -> str:
        values = sorted(s for r in rounds[variant] for s in r.stretches)
        if not values:
            return "-"
        value = median(values) if pct == "median" else values[-1]
        return f"{value:.2f}x"

    rows: list[tuple[str, Callable[[str], str]]] = [
        ("tests failed (ctest)", lambda v: total(v, "failed")),
        (f"deadlines missed (wall > {STRETCH_LIMIT:g}x CPU)", lambda v: total(v, "missed")),
        ("wall / CPU of a test, median", lambda v: stretch(v, "median")),
        ("wall / CPU of a test, worst", lambda v: stretch(v, "max")),
        ("suite wall time (median)", lambda v: secs(median([r.wall for r in rounds[v]]))),
        (f"ideal: {tests} x {work:g} s / {cpus} CPUs", lambda v: secs(ideal)),
    ]
    for label, cell in rows:
        section.rows.append((label, *(cell(variant) for variant in VARIANTS)))
    missed = sum(r.missed + r.failed for r in rounds[VARIANTS[1]])
    section.notes.append(
        "Target: with cpu=1 per test no deadline missed and no test failed: "
        f"{verdict(missed == 0)}."
    )
    section.notes.append(
        f"Each test is our RUNNER (`{ctx.runners[OURS].name}`, plain `add_test`) around a "
        f"Python loop calibrated to {work:g} s of CPU; it fails when its wall time exceeds "
        f"{STRETCH_LIMIT:g}x its own CPU time. With `cpu=1` every test passes "
        f"`--env ROS_ISOLATED_TEST_RESOURCES=cpu=1` and ctest's environment sets "
        f"`ROS_ISOLATED_TEST_CAPACITY=cpu={cpus}` (the CPUs this process may use, the "
        f"default): at most {cpus} tests work at once, the others wait in their runner "
        f"(ctest counts that as their run time). Other load on the machine stretches both "
        f"columns alike."
    )
    return section


if __name__ == "__main__":
    print("run it through benches/run.py --only cpu_load", file=sys.stderr)
    sys.exit(2)
