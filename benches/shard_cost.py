"""13. What a share's decision costs a test: reading the split, the durations file, the plan.

A ctest RUNNER runs one test, so in a split each one reads the durations file and plans
the workspace's tests to answer for its own. This measures,
in fresh interpreters of this venv (bytecode cached, as under colcon), the RUNNER's own
imports (``ros_isolated_test.ament.args``) alone and then with
``shard.selection.select`` + ``runs`` + ``properties`` on top: by count (no file), and
with durations files of 1,000 and 10,000 tests (about 30 KB and 300 KB). Wall time added
over the imports alone, medians, interleaved; and, inside the process, where the time
goes (reading the file, planning, the fingerprint). Ours only: upstream has no split.

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

from common import BOOTSTRAP_MARK, Context, Section, median, ms, progress, run_timed

from ros_isolated_test.shard.durations import measured, write

BASELINE = "ros_isolated_test.ament.args"
#: Tests in each durations file measured; 0: no file (by count).
SIZES = (0, 1_000, 10_000)
#: The target: what a 10,000-test file may add to a test, at most.
TARGET_SECONDS = 0.030
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


def run(ctx: Context) -> Section:
    """For benches/run.py: this venv's interpreter and environment, the run's scratch."""
    return measure(ctx.python, ctx.env, ctx.quick, ctx.scratch("shard_cost"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer runs")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as work:
        print(measure(sys.executable, dict(os.environ), args.quick, Path(work)).render())


if __name__ == "__main__":
    main()
