"""13. What a share's decision costs a test: reading the split, the durations file, the plan.

A ctest RUNNER runs one test, so in a split each one reads the durations file and plans
the workspace's tests to answer for its own. This measures,
in fresh interpreters of this venv (bytecode cached, as under colcon), the RUNNER's own
imports (``ros_isolated_test.ament.args``) alone and then with
``shard.selection.select`` + ``runs`` + ``properties`` on top: by count (no file), and
with durations files of 1,000 and 10,000 tests (about 30 KB and 300 KB). Wall time added
over the imports alone, medians, interleaved; and, inside the process, where the time
goes (reading the file, planning, the fingerprint). Ours only: upstream has no split.

Then what a machine of a split pays for the other shares' tests, as a new user meets it:
one ament_cmake package of 120 no-op ``ament_add_test`` tests (``--quick``: 40) through
the zero-edit include, ``colcon test --ctest-args -j1`` whole, as share 1/4
(``ROS_ISOLATED_TEST_SHARD``), and an ament_cmake package with no tests, best of 3
(``--quick``: 2). The share's fair part is the empty package's wall plus its share of the
tests' cost: ``empty + k/n x (whole - empty)`` for k of the n tests; its wall over that
part must be at most 1.10 (ctest disables the other shares' tests, no RUNNER starts).

Run alone: ``python benches/shard_cost.py`` (``--quick``: fewer runs).
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from pathlib import Path

from common import BOOTSTRAP_MARK, REPO, Context, Section, median, ms, progress, run_timed

from ros_isolated_test.shard.durations import measured, write
from ros_isolated_test.shard.selection import select

sys.path.insert(0, str(REPO / "examples"))
import crosstalk_workspace

BASELINE = "ros_isolated_test.ament.args"
#: Tests in each durations file measured; 0: no file (by count).
SIZES = (0, 1_000, 10_000)
#: The target: what a 10,000-test file may add to a test, at most.
TARGET_SECONDS = 0.030
#: The package of no-op tests (--quick: fewer), the share measured, and its target: the
#: share's wall over its fair part.
PACKAGE_TESTS = 120
QUICK_PACKAGE_TESTS = 40
PACKAGE_SHARE = "1/4"
PACKAGE_TARGET = 1.10
MANIFEST = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name><version>0.1.0</version><description>No-op tests.</description>
  <maintainer email="maintainer@example.com">Example Maintainer</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
_ASK = """
import os, time
import {baseline}
start = time.process_time()
from ros_isolated_test.shard.selection import select
imported = time.process_time()
selection = select(os.environ)
read = time.process_time()
selection.runs("pkg_27", "test_77")  # a test the files know
planned = time.process_time()
selection.properties()
done = time.process_time()
print(imported - start, read - imported, planned - read, done - planned)
"""


def _environment(base: Mapping[str, str], durations: Path | None) -> dict[str, str]:
    env = {key: value for key, value in base.items() if not key.startswith("ROS_ISOLATED_TEST_")}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env[BOOTSTRAP_MARK] = "1"
    if durations is not None:
        env["ROS_ISOLATED_TEST_SHARD"] = "2/4"
        if durations.name != "none":
            env["ROS_ISOLATED_TEST_DURATIONS"] = str(durations)
    return env


def _file(where: Path, count: int) -> Path:
    """A durations file of ``count`` tests, skewed as ROS suites are (lognormal seconds)."""
    rng = random.Random(count)
    tests = {f"pkg_{n % 50}/test_{n}": min(rng.lognormvariate(0, 1.5), 3600) for n in range(count)}
    path = where / f"durations-{count}.json"
    write(path, measured(tests))
    return path


def measure(python: str, base_env: Mapping[str, str], quick: bool, work: Path) -> Section:
    """The table: each configuration's wall time added, and where the time goes inside."""
    reps = 5 if quick else 31
    files: dict[str, Path | None] = {"imports alone": None}
    for size in SIZES:
        files["by count" if size == 0 else f"{size:,} tests"] = (
            work / "none" if size == 0 else _file(work, size)
        )
    envs = {label: _environment(base_env, path) for label, path in files.items()}

    def once(label: str) -> tuple[float, list[float]]:
        if files[label] is None:
            return run_timed([python, "-c", f"import {BASELINE}"], envs[label]).seconds, []
        code = _ASK.format(baseline=BASELINE)
        timed = run_timed([python, "-c", code], envs[label])
        inner = subprocess.run(
            [python, "-c", code], env=envs[label], capture_output=True, text=True, check=True
        )
        return timed.seconds, [float(part) for part in inner.stdout.split()]

    labels = list(files)
    for label in labels:  # warm-up: bytecode written, caches filled
        once(label)
    walls: dict[str, list[float]] = {label: [] for label in labels}
    parts: dict[str, list[list[float]]] = {label: [] for label in labels}
    progress(f"shard cost: {len(labels)} configurations, {reps} runs each")
    for rep in range(reps):
        for label in labels if rep % 2 == 0 else list(reversed(labels)):
            seconds, inside = once(label)
            walls[label].append(seconds)
            parts[label].append(inside)
    baseline = median(walls["imports alone"])
    section = Section(
        "13. A share's decision: what `select` + `runs` + `properties` add to a RUNNER",
        ("configuration", "wall time added", "import", "read the split", "plan", "fingerprint"),
    )
    added_at_most = 0.0
    for label in labels[1:]:
        added = median(walls[label]) - baseline
        added_at_most = max(added_at_most, added)
        columns = [ms(median([run[index] for run in parts[label]])) for index in range(4)]
        section.rows.append((label, f"{added * 1000:+.1f} ms", *columns))
    met = added_at_most <= TARGET_SECONDS
    section.notes.append(
        f"Python {sys.version.split()[0]}; median of {reps} fresh interpreters each, "
        f"interleaved, against the RUNNER's imports alone ({ms(baseline)}). The inner columns "
        "are CPU time (which waiting for a loaded machine's CPUs does not inflate), taken "
        "inside a separate run of each: importing the shard package (after the "
        "RUNNER's imports), reading "
        "the variables and the file (`select`), planning (the first `runs`), and the "
        "fingerprint results record (`properties`). Target: a 10,000-test file adds at most "
        f"{TARGET_SECONDS * 1000:.0f} ms to a test: {'met' if met else '**NOT met**'}."
    )
    return section


def _package(src: Path, name: str, count: int) -> None:
    """An ament_cmake package of ``count`` no-op tests that name no runner."""
    folder = src / name
    folder.mkdir(parents=True)
    (folder / "package.xml").write_text(MANIFEST.format(name=name))
    tests = "".join(
        f"  ament_add_test(t_{n} COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n"
        for n in range(count)
    )
    (folder / "CMakeLists.txt").write_text(
        f"cmake_minimum_required(VERSION 3.15)\nproject({name} NONE)\n"
        f"find_package(ament_cmake REQUIRED)\nif(BUILD_TESTING)\n{tests}endif()\nament_package()\n"
    )


def package_share(python: str, base_env: Mapping[str, str], quick: bool, work: Path) -> list[str]:
    """The package of no-op tests whole, as one share, and an empty package: note lines."""
    count = QUICK_PACKAGE_TESTS if quick else PACKAGE_TESTS
    reps = 2 if quick else 3
    root = work / "package_share"
    _package(root / "src", "noop_tests", count)
    _package(root / "src", "no_tests", 0)
    env = crosstalk_workspace.colcon_env(crosstalk_workspace.Toolchain(base_env=dict(base_env)))
    for name in ("ROS_ISOLATED_TEST_SHARD", "ROS_ISOLATED_TEST_DURATIONS", "PYTHONPATH"):
        env.pop(name, None)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.pop("COLCON_DEFAULTS_FILE", None)
    env["COLCON_HOME"] = str(root / "colcon-home")
    include = subprocess.run(
        [python, "-m", "ros_isolated_test", "cmake-include"], env=env,
        capture_output=True, text=True, check=True, timeout=60,
    ).stdout.strip()  # fmt: skip
    progress(f"shard cost: a package of {count} no-op tests, colcon build")
    built = subprocess.run(
        ["colcon", "build", "--cmake-args", f"-DCMAKE_PROJECT_INCLUDE={include}",
         f"-DPython3_EXECUTABLE={python}"],
        cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        check=False,
    )  # fmt: skip
    if built.returncode != 0:
        raise RuntimeError(f"colcon build failed:\n{built.stdout[-4000:]}")
    runs = {
        "whole package": ("noop_tests", {}),
        f"share {PACKAGE_SHARE}": ("noop_tests", {"ROS_ISOLATED_TEST_SHARD": PACKAGE_SHARE}),
        "empty package": ("no_tests", {}),
    }

    def once(package: str, extra: Mapping[str, str]) -> float:
        command = ["colcon", "test", "--packages-select", package, "--ctest-args", "-j1"]
        return run_timed(command, {**env, **extra}, cwd=root).seconds

    for package, extra in runs.values():  # warm-up
        once(package, extra)
    walls: dict[str, list[float]] = {label: [] for label in runs}
    progress(f"shard cost: the package whole, as share {PACKAGE_SHARE}, empty: {reps} runs each")
    for rep in range(reps):
        for label in runs if rep % 2 == 0 else list(reversed(runs)):
            walls[label].append(once(*runs[label]))
    best = {label: min(values) for label, values in walls.items()}
    selection = select({"ROS_ISOLATED_TEST_SHARD": PACKAGE_SHARE})
    assert selection is not None
    share_tests = sum(selection.runs("noop_tests", f"t_{n}") for n in range(count))
    empty, whole = best["empty package"], best["whole package"]
    fair = empty + share_tests / count * (whole - empty)
    over = best[f"share {PACKAGE_SHARE}"] / fair
    said = "met" if over <= PACKAGE_TARGET else f"**NOT met** (by {over / PACKAGE_TARGET - 1:.0%})"
    return [
        "",
        f"A split machine's share of one package ({count} no-op `ament_add_test`s, zero-edit "
        f"include, `colcon test --ctest-args -j1`, best of {reps}):",
        "",
        "| run | tests run | wall |",
        "|---|---|---|",
        f"| whole package | {count} | {whole:.2f} s |",
        f"| share {PACKAGE_SHARE} | {share_tests} | {best[f'share {PACKAGE_SHARE}']:.2f} s |",
        f"| empty package | 0 | {empty:.2f} s |",
        "",
        f"The share's fair part: {empty:.2f} s + {share_tests}/{count} x ({whole:.2f} s - "
        f"{empty:.2f} s) = {fair:.2f} s; its wall is {over:.2f} x that. Target: at most "
        f"{PACKAGE_TARGET:.2f} x: {said}.",
    ]


def run(ctx: Context) -> Section:
    """For benches/run.py: this venv's interpreter and environment, the run's scratch."""
    section = measure(ctx.python, ctx.env, ctx.quick, ctx.scratch("shard_cost"))
    section.notes += package_share(ctx.python, ctx.env, ctx.quick, ctx.scratch("shard_cost"))
    return section


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer runs")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as work:
        section = measure(sys.executable, dict(os.environ), args.quick, Path(work))
        section.notes += package_share(sys.executable, dict(os.environ), args.quick, Path(work))
        print(section.render())


if __name__ == "__main__":
    main()
