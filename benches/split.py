"""15. A workspace's tests split over N CI machines: the slowest machine against the bound.

When one machine takes too long, CI splits the tests over N machines and waits for the
slowest (the makespan). One synthetic workspace (:data:`FULL`: 5 ament_cmake packages,
48 tests, skewed as ROS suites are: one package holds the three longest tests, as
navigation2's controller and planner tests dominated its suite; most tests are short;
every test ``sleep``\\ s, so 2 CPUs serve 4 simulated machines), built once per machine
with the zero-edit recipe, is split four ways for N = 2 and 4:

- (a) ours, balanced by a durations file written (``report --durations``) from an
  earlier run's trees (the first run of (b), its N machines' trees merged):
  ``ROS_ISOLATED_TEST_SHARD=k/N ROS_ISOLATED_TEST_DURATIONS=FILE``;
- (b) ours without one, by count: ``ROS_ISOLATED_TEST_SHARD=k/N``;
- (c) by package, as navigation2's CircleCI did (``circleci tests split
  --split-by=timings`` over the package list): the packages, by their total time in the
  same earlier run, each onto the least loaded machine, longest first;
  ``colcon test --packages-select ...``;
- (d) ctest's stride: ``colcon test --ctest-args -I k,,N`` (every N-th test of each
  package).

Each simulated machine has a build tree of its own (``--build-base``, ``--install-base``),
a lock directory of its own and, where the system allows it, a network namespace of its
own; the N machines of a split run at once. Each runs its share one test at a time
(``--executor sequential --ctest-args -j1``): the lower bound, and every strategy's
balance, are about a machine's serial time, and on 2 CPUs four machines with several
tests each at once would measure start-up contention rather than the split. The makespan
is the slowest machine's ``colcon test`` wall time; the lower bound is the larger of the
measured total over N and the longest test (``shard --plan``). Every strategy is checked
to run every test exactly once (from the result files the machines left). Last, the
durations file is made stale (one test it names removed, one test of the workspace
missing from it: a new one) and (a) is run again: every test must still run once.
"""

from __future__ import annotations

import json
import math
import os
import random
import shutil
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from common import OURS, REPO, Context, Section, progress, ratio, secs

from ros_isolated_test.report.shard_durations import named_tests
from ros_isolated_test.report.tree import read_tree
from ros_isolated_test.shard.durations import MICROS, Durations, load, write

sys.path.insert(0, str(REPO / "examples"))
import crosstalk_workspace

#: Package -> its tests' seconds. The longest tests share one package (the package split's
#: trouble); most are short.
FULL: dict[str, list[float]] = {
    "split_core": [60.0, 36.0, 24.0, *[1.5] * 5],
    "split_nav": [*[9.0] * 4, *[1.5] * 6],
    "split_util": [1.5] * 12,
    "split_msgs": [0.9] * 10,
    "split_viz": [12.0, *[1.5] * 7],
}
#: --quick: the same workspace shape, every test 30 times shorter.
QUICK_SCALE = 1 / 30
TOTALS = (2, 4)
QUICK_TOTALS = (2,)
#: A machine's run that takes longer than this is stuck.
RUN_TIMEOUT = 1800
BLOCK_COORDINATOR = "colcon_core.shell.ros_domain_id:colcon_core.event_handler.ros_domain_id"
SEQUENTIAL = ("--executor", "sequential")
CMAKE = """\
cmake_minimum_required(VERSION 3.15)
project({package} NONE)
find_package(ament_cmake REQUIRED)
if(BUILD_TESTING)
{tests}endif()
ament_package()
"""
PACKAGE_XML = """\
<?xml version="1.0"?>
<package format="3">
  <name>{package}</name><version>0.1.0</version>
  <description>The split benchmark's package: sleeping tests.</description>
  <maintainer email="maintainers@ros-isolated-test.org">ros-isolated-test maintainers</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
STRATEGIES = {
    "a": "(a) ours, by a durations file",
    "b": "(b) ours, by count",
    "c": "(c) by package, by timings (navigation2's CircleCI)",
    "d": "(d) ctest's stride (`-I k,,N`)",
}


def layout(scale: float) -> dict[str, list[tuple[str, float]]]:
    """Package -> its tests (name, seconds), registered in a shuffled order (seeded)."""
    chance = random.Random(15)
    found: dict[str, list[tuple[str, float]]] = {}
    for package, seconds in FULL.items():
        tests = [(f"{package}_t{n:02d}", round(s * scale, 3)) for n, s in enumerate(seconds)]
        chance.shuffle(tests)
        found[package] = tests
    return found


def generate(src: Path, packages: Mapping[str, Sequence[tuple[str, float]]]) -> None:
    """Write the packages: each test ``sleep S`` through ``ament_add_test``."""
    for package, tests in packages.items():
        folder = src / package
        folder.mkdir(parents=True, exist_ok=True)
        lines = "".join(
            f"  ament_add_test({name} COMMAND sleep {seconds:g} TIMEOUT 300 "
            "GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n"
            for name, seconds in tests
        )
        (folder / "CMakeLists.txt").write_text(CMAKE.format(package=package, tests=lines))
        (folder / "package.xml").write_text(PACKAGE_XML.format(package=package))


def network_wrapper() -> tuple[list[str], str]:
    """The words that put a command in a network namespace of its own, and what they are."""
    unshare, ip = shutil.which("unshare"), shutil.which("ip")
    if unshare is None or ip is None:
        return [], "no network namespace of their own (no unshare or ip command)"
    for extra in ([], ["--map-root-user"]):
        command = [
            unshare,
            "--net",
            *extra,
            "--",
            "sh",
            "-c",
            'ip link set lo up && exec "$@"',
            "sh",
        ]
        if subprocess.run([*command, "true"], capture_output=True, check=False).returncode == 0:
            return command, "a network namespace of its own each (loopback only)"
    return [], "no network namespace of their own (not allowed here)"


@dataclass(frozen=True)
class Machines:
    """The simulated machines: one build tree, lock directory and log folder each."""

    root: Path
    env: Mapping[str, str]
    wrapper: Sequence[str]

    def base(self, machine: int) -> Path:
        return self.root / f"machine-{machine}"

    def colcon(self, machine: int, verb: str, args: Sequence[str], extra: Mapping[str, str]
               ) -> tuple[float, str]:  # fmt: skip
        """``colcon VERB`` on machine ``machine``'s own tree: wall seconds and output."""
        base = self.base(machine)
        command = [
            *self.wrapper, "colcon", "--log-base", str(base / "log"), verb,
            "--base-paths", str(self.root / "src"), "--build-base", str(base / "build"),
            "--install-base", str(base / "install"), *args,
        ]  # fmt: skip
        env = {**self.env, "ROS_ISOLATED_TEST_LOCK_DIR": str(base / "locks"), **extra}
        start = time.perf_counter()
        done = subprocess.run(
            command, cwd=self.root, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, timeout=RUN_TIMEOUT, check=False,
        )  # fmt: skip
        wall = time.perf_counter() - start
        if verb == "build" and done.returncode != 0:
            raise RuntimeError(f"colcon build on machine {machine} failed:\n{done.stdout[-4000:]}")
        return wall, done.stdout

    def clear(self, machine: int) -> None:
        """What the machine's last run left: a fresh CI machine has no results."""
        for results in (self.base(machine) / "build").glob("*/test_results"):
            shutil.rmtree(results)

    def ran(self, machine: int) -> list[str]:
        """The identities of the tests machine ``machine`` left results for."""
        return [
            key
            for item in read_tree([self.base(machine) / "build"])
            for key, _seconds in named_tests(item)
        ]

    def at_once(self, runs: Sequence[tuple[int, Sequence[str], Mapping[str, str]]]
                ) -> tuple[list[float], list[list[str]]]:  # fmt: skip
        """``colcon test`` on each (machine, args, extra env) at once: walls, tests each ran."""
        for machine, _args, _extra in runs:
            self.clear(machine)
        walls = [math.nan] * len(runs)

        def one(index: int, machine: int, args: Sequence[str], extra: Mapping[str, str]) -> None:
            walls[index] = self.colcon(machine, "test", [*SEQUENTIAL, *args], extra)[0]

        threads = [
            threading.Thread(target=one, args=(index, *run)) for index, run in enumerate(runs)
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        return walls, [self.ran(machine) for machine, _args, _extra in runs]


def by_package(durations: Durations, total: int) -> list[list[str]]:
    """Packages by their total time, longest first, each onto the least loaded machine."""
    sums: Counter[str] = Counter()
    for key, micros in durations.micros.items():
        sums[key.split("/", 1)[0]] += micros
    loads = [0] * total
    shares: list[list[str]] = [[] for _ in range(total)]
    for package, micros in sorted(sums.items(), key=lambda item: (-item[1], item[0])):
        least = loads.index(min(loads))
        shares[least].append(package)
        loads[least] += micros
    return shares


def runs_of(strategy: str, total: int, durations_file: Path, durations: Durations
            ) -> list[tuple[int, Sequence[str], Mapping[str, str]]]:  # fmt: skip
    """Each machine's ``colcon test`` arguments and environment for ``strategy``."""
    machines = range(1, total + 1)
    if strategy == "a":
        named = {"ROS_ISOLATED_TEST_DURATIONS": str(durations_file)}
        return [(k, (), {"ROS_ISOLATED_TEST_SHARD": f"{k}/{total}", **named}) for k in machines]
    if strategy == "b":
        return [(k, (), {"ROS_ISOLATED_TEST_SHARD": f"{k}/{total}"}) for k in machines]
    if strategy == "c":
        shares = by_package(durations, total)
        return [(k, ("--packages-select", *shares[k - 1]), {}) for k in machines if shares[k - 1]]
    return [(k, ("--ctest-args", "-I", f"{k},,{total}"), {}) for k in machines]


def lower_bound(ctx: Context, durations_file: Path, total: int) -> float:
    """The larger of the total over N and the longest test, as ``shard --plan`` says it."""
    done = subprocess.run(
        [sys.executable, "-m", "ros_isolated_test", "shard", "--plan", "--json", "--durations",
         str(durations_file), "--total", str(total)],
        env=ctx.environment(OURS), capture_output=True, text=True, check=True, timeout=120,
    )  # fmt: skip
    bound: float = json.loads(done.stdout)["lower_bound_seconds"]
    return bound


def once_each(machines: Sequence[Sequence[str]], expected: set[str]) -> str:
    """Whether every test ran exactly once: ``48 of 48, each once``, or what went wrong."""
    counts = Counter(key for ran in machines for key in ran)
    twice = sorted(key for key, count in counts.items() if count > 1)
    missing = sorted(expected - set(counts))
    if not twice and not missing:
        return f"{len(expected)} of {len(expected)}, each once"
    said = [f"{len(set(counts) & expected)} of {len(expected)}"]
    if missing:
        said.append(f"**{len(missing)} never** ({missing[0]}...)")
    if twice:
        said.append(f"**{len(twice)} twice** ({twice[0]}...)")
    return ", ".join(said)


def stale(durations: Durations, expected: set[str], where: Path) -> tuple[Path, str, str]:
    """The file with one test it knows removed from the workspace and one new one unknown."""
    known = sorted(durations.micros)
    new = known[len(known) // 2]  # a test the file will not know
    micros = {key: value for key, value in durations.micros.items() if key != new}
    gone = "split_util/split_util_t99"  # a test the workspace no longer has
    micros[gone] = MICROS
    assert gone not in expected and new in expected
    path = where / "durations-stale.json"
    write(path, Durations(micros))
    return path, new, gone


def run(ctx: Context) -> Section:
    """Build per machine; (b) first, for the durations file; then each split, interleaved."""
    scale = QUICK_SCALE if ctx.quick else 1.0
    totals = QUICK_TOTALS if ctx.quick else TOTALS
    packages = layout(scale)
    root = ctx.scratch("split")
    generate(root / "src", packages)
    expected = {f"{package}/{name}" for package, tests in packages.items() for name, _ in tests}
    wrapper, network = network_wrapper()
    env = crosstalk_workspace.colcon_env(
        crosstalk_workspace.Toolchain(base_env=ctx.environment(OURS))
    )
    for name in ("ROS_ISOLATED_TEST_SHARD", "ROS_ISOLATED_TEST_DURATIONS", "PYTHONPATH"):
        env.pop(name, None)
    env.update(
        {"COLCON_HOME": str(root / "colcon-home"), "COLCON_EXTENSION_BLOCKLIST": BLOCK_COORDINATOR}
    )
    env.pop("COLCON_DEFAULTS_FILE", None)
    machines = Machines(root, env, wrapper)
    include = subprocess.run(
        [sys.executable, "-m", "ros_isolated_test", "cmake-include"], env=env,
        capture_output=True, text=True, check=True, timeout=60,
    ).stdout.strip()  # fmt: skip
    most = max(totals)
    progress(
        f"split: colcon build on {most} machines ({len(expected)} tests, {len(packages)} packages)"
    )
    cmake_args = [f"-DCMAKE_PROJECT_INCLUDE={include}", f"-DPython3_EXECUTABLE={sys.executable}"]
    for machine in range(1, most + 1):
        machines.colcon(machine, "build", ["--cmake-args", *cmake_args], {})
    # The earlier run: (b) at the most machines, whose merged trees give the durations file.
    progress(f"split: N={most}, {STRATEGIES['b']} (the earlier run: the durations file)")
    done: dict[tuple[int, str], tuple[list[float], list[list[str]]]] = {}
    done[(most, "b")] = machines.at_once(runs_of("b", most, root, Durations({})))
    durations_file = root / "durations.json"
    subprocess.run(
        [sys.executable, "-m", "ros_isolated_test", "report", "--durations", str(durations_file),
         *(str(machines.base(machine) / "build") for machine in range(1, most + 1))],
        env=env, capture_output=True, text=True, check=True, timeout=300,
    )  # fmt: skip
    durations = load(durations_file)
    bounds = {total: lower_bound(ctx, durations_file, total) for total in totals}
    for number, total in enumerate(totals):
        order = list(STRATEGIES) if number % 2 == 0 else list(reversed(STRATEGIES))
        for strategy in order:
            if (total, strategy) not in done:
                progress(f"split: N={total}, {STRATEGIES[strategy]}")
                runs = runs_of(strategy, total, durations_file, durations)
                done[(total, strategy)] = machines.at_once(runs)
    section = Section(
        f"15. {len(expected)} tests in {len(packages)} packages split over N machines, each "
        "one test at a time: the slowest machine's `colcon test` (makespan)",
        ("N", "split", "makespan", "/ lower bound", "slowest / fastest machine", "tests run"),
    )
    results = {key: max(walls) for key, (walls, _ran) in done.items()}
    for total in totals:
        for strategy, label in STRATEGIES.items():
            walls, ran_here = done[(total, strategy)]
            fastest = secs(min(walls)) if len(walls) == total else "0 s (no package)"
            section.rows.append((
                str(total), label, secs(max(walls)), ratio(max(walls), bounds[total]),
                f"{secs(max(walls))} / {fastest}", once_each(ran_here, expected),
            ))  # fmt: skip
        section.rows.append((str(total), "lower bound", secs(bounds[total]), "1.00", "", ""))
    for total in TOTALS:
        if total not in totals:
            section.rows.append((str(total), "all four", "skipped in --quick", "", "", ""))
    stale_file, new, gone = stale(durations, expected, root)
    progress(f"split: N={most}, (a) with a stale durations file")
    walls, ran_stale = machines.at_once(runs_of("a", most, stale_file, durations))
    section.notes.append(_verdicts(results, bounds, totals, ctx.quick))
    section.notes.append(
        f"Stale durations file (`{new}` missing from it: a new test; `{gone}` in it but "
        f"gone from the workspace), (a) at N={most}: {once_each(ran_stale, expected)}, "
        f"makespan {secs(max(walls))}."
    )
    walls, ran_a = done[(most, "a")]
    fixed = [
        wall - sum(durations.micros.get(key, 0) for key in ran) / MICROS
        for wall, ran in zip(walls, ran_a, strict=True)
    ]
    section.notes.append(
        f"What a machine pays besides its tests, in (a) at N={most} (its wall time less its "
        f"tests' measured time): {secs(min(fixed))} to {secs(max(fixed))}: colcon's start, "
        "each package's environment set-up and ctest, and the one process per package that "
        "plans its share (ctest disables the other shares' tests, so no RUNNER starts for "
        "them). It is what keeps a split's makespan above the bound, the same on every "
        "machine."
    )
    measured_total = sum(durations.micros.values()) / MICROS
    longest = max(durations.micros.values()) / MICROS
    section.notes.append(
        f"The durations file comes from the earlier run, (b) at N={most} (its machines' trees "
        f"merged by `report --durations`): measured total {secs(measured_total)}, longest "
        f"test {secs(longest)}. Tests `sleep`; each package's tests are registered "
        "in a shuffled order (seeded), as a suite's order says nothing of its durations. "
        f"The machines: {network}, a lock directory and a build tree each (built once, "
        f"with `-DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)`); the N machines "
        "of a split run at once, each `colcon test --executor sequential --ctest-args -j1`; "
        f"{len(os.sched_getaffinity(0))} CPUs, the times move with the machine's load."
    )
    return section


def _verdicts(results: Mapping[tuple[int, str], float], bounds: Mapping[int, float],
              totals: Sequence[int], quick: bool) -> str:  # fmt: skip
    """Target for (a): within 10% of the lower bound, and no worse than the better of (c), (d)."""
    said = []
    for total in totals:
        ours = results[(total, "a")]
        best_other = min(results[(total, "c")], results[(total, "d")])
        within = ours <= 1.10 * bounds[total]
        no_worse = ours <= best_other
        met = within and no_worse
        said.append(
            f"N={total}: (a) {ours / bounds[total]:.2f} x the bound, "
            f"{ours / best_other:.2f} x the better of (c) and (d): "
            + ("met" if met else "**NOT met**")
        )
    scale = (
        " (--quick: every test 20 times shorter, so the machines' fixed start-up weighs "
        "far more than in a full run; the target is read on a full run)"
        if quick
        else ""
    )
    return (
        "Target for (a): at most 1.10 x the lower bound and no worse than the better of (c) "
        f"and (d). {'; '.join(said)}{scale}."
    )


if __name__ == "__main__":
    print("run it through benches/run.py --only split", file=sys.stderr)
    sys.exit(2)
