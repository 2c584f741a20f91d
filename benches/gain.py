"""14. What a user gains: a workspace of rclpy tests, serialised as CI tools do, against ours.

The ROS users who need isolation most turn parallelism off instead: industrial_ci runs
``colcon test --executor sequential --ctest-args -j1`` unless ``PARALLEL_TESTS`` is set,
Autoware's CI moved to ``--executor sequential``, ros2_control and MoveIt test one test
at a time. This benchmark measures what switching to ours buys. One workspace of 8
ament_cmake packages of 4 tests each (:data:`FULL`), generated from one template, every
test examples/crosstalk_demo's token talker (real rclpy over Fast DDS: it publishes a
token of its own on one topic all tests share and fails on hearing any other), is tested
five ways:

- (a) as industrial_ci does by default: one package, one test at a time, ament's own
  ``run_test.py`` (correct, slow);
- (b) colcon's parallel executor and ``ctest -j``, every test at once, no isolation;
- (c) the same with colcon's domain-ID coordinator active (one ID per package's task:
  the tests of one package still share it), and (c') with the tests of each package one
  at a time (``-j1``), the fastest correct run it allows;
- (d) ours with zero edits (built with ``-DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test
  cmake-include)``), the (b) command.

Two builds: ament's runner for (a) to (c'), ours for (d). Wall time is that of the whole
``colcon test``, as a user waits for it; failures come from the result files each test
left (a test without one failed), and what each talker heard from its own record
(``CROSSTALK_RECORD_DIR``). Runs are interleaved, the order flipped every repetition.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from common import (
    OURS,
    REPO,
    Context,
    Section,
    median,
    progress,
    quotient,
    ratio,
    secs,
)

sys.path.insert(0, str(REPO / "examples"))
import crosstalk_workspace

#: Packages, tests per package, seconds each talker listens after hearing itself.
FULL = (8, 4, 4.0)
QUICK = (2, 2, 1.0)
#: The talker every test runs, and where colcon's coordinator is installed apart.
TALKER_DIR = REPO / "examples" / "crosstalk_demo" / "test"
COORDINATOR_DIR = Path(sys.prefix) / "colcon-coordinator"
#: Keeps colcon's coordinator out of every run but (c) and (c'), should it be installed in the venv.
BLOCK_COORDINATOR = "colcon_core.shell.ros_domain_id:colcon_core.event_handler.ros_domain_id"
#: Not run in --quick: (c') only adds a row between (a) and (d).
QUICK_SKIPS = frozenset({"c'"})
#: A run that takes longer than this is stuck (a test's own TIMEOUT is 60 s).
RUN_TIMEOUT = 1800

TALK = '''\
"""One test of the gain benchmark: crosstalk_demo's token talker, listening ARGV[2] s."""
import sys

sys.path.insert(0, {talker_dir!r})
import token_talker

token_talker.LISTEN_S = float(sys.argv[2])
sys.exit(token_talker.main(sys.argv[:2]))
'''
CMAKE = """\
cmake_minimum_required(VERSION 3.15)
project({package} NONE)

find_package(ament_cmake REQUIRED)

if(BUILD_TESTING)
  foreach(_token IN ITEMS {tokens})
    ament_add_test(talker_${{_token}}
      COMMAND "${{Python3_EXECUTABLE}}" [==[{talk}]==] "${{_token}}" {listen}
      TIMEOUT 60
      GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
  endforeach()
endif()

ament_package()
"""
PACKAGE_XML = """\
<?xml version="1.0"?>
<package format="3">
  <name>{package}</name>
  <version>0.1.0</version>
  <description>The gain benchmark's package {index}: {tests} token talkers.</description>
  <maintainer email="maintainers@ros-isolated-test.org">ros-isolated-test maintainers</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <test_depend>ament_cmake_test</test_depend>
  <test_depend>rclpy</test_depend>
  <test_depend>std_msgs</test_depend>
  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""


@dataclass(frozen=True)
class Way:
    """One way of running the workspace's tests: which build, which command, coordinator."""

    key: str
    label: str
    build: str
    args: tuple[str, ...]
    coordinator: bool = False


@dataclass(frozen=True)
class Round:
    """One ``colcon test`` of the workspace."""

    wall: float
    #: Test name -> passed, from its result file (absent: failed).
    passed: Mapping[str, bool]
    #: Tests that heard a token of their own package's other tests / of another package's.
    heard_own_package: int
    heard_other_package: int
    #: The distinct ROS_DOMAIN_IDs the tests ran on ("unset" for none).
    domains: frozenset[str]


def layout(packages: int, tests: int) -> dict[str, list[str]]:
    """Package name -> its tests' tokens: ``gain_p1`` has ``p1t1``..``p1t<tests>``."""
    return {
        f"gain_p{p}": [f"p{p}t{t}" for t in range(1, tests + 1)] for p in range(1, packages + 1)
    }


def ways(packages: int, tests: int) -> list[Way]:
    """The five runs, each the colcon command a user would type (options after ``test``)."""
    together = ("--parallel-workers", str(packages), "--ctest-args", f"-j{tests}")
    return [
        Way("a", "(a) industrial_ci's default: sequential, ament's runner", "plain",
            ("--executor", "sequential", "--ctest-args", "-j1")),
        Way("b", "(b) colcon in parallel, no isolation", "plain", together),
        Way("c", "(c) colcon's domain-ID coordinator, in parallel", "plain", together, True),
        Way("c'", "(c') colcon's coordinator, a package's tests one at a time", "plain",
            ("--parallel-workers", str(packages), "--ctest-args", "-j1"), True),
        Way("d", "(d) ours, zero edits, in parallel", "ours", together),
    ]  # fmt: skip


def generate(root: Path, packages: Mapping[str, Sequence[str]], listen: float) -> Path:
    """Write the workspace's ``src/`` from the template; return the workspace root."""
    talk = root / "talk.py"
    talk.write_text(TALK.format(talker_dir=str(TALKER_DIR)))
    for index, (package, tokens) in enumerate(packages.items(), start=1):
        folder = root / "src" / package
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "CMakeLists.txt").write_text(
            CMAKE.format(package=package, tokens=" ".join(tokens), talk=talk, listen=listen)
        )
        (folder / "package.xml").write_text(
            PACKAGE_XML.format(package=package, index=index, tests=len(tokens))
        )
    return root


def result_failed(result: Path) -> bool:
    """Whether a test failed, from the result file it left: none, unreadable, or a failure."""
    try:
        root = ET.parse(result).getroot()
    except (OSError, ET.ParseError):
        return True
    return any(True for tag in ("failure", "error") for _ in root.iter(tag))


def crosstalk(records: Mapping[str, crosstalk_workspace.Record], package_of: Mapping[str, str]
              ) -> tuple[int, int]:  # fmt: skip
    """How many tests heard a token of their own package's tests, and of another package's."""
    own = other = 0
    for token, record in records.items():
        heard = {package_of.get(foreign, "?") for foreign in record.foreign}
        own += package_of[token] in heard
        other += bool(heard - {package_of[token]})
    return own, other


class Workspace:
    """The generated packages, their two builds, and colcon run on them."""

    def __init__(self, ctx: Context, root: Path, packages: Mapping[str, Sequence[str]]) -> None:
        self.root = root
        self.packages = packages
        self.package_of = {token: p for p, tokens in packages.items() for token in tokens}
        toolchain = crosstalk_workspace.Toolchain(base_env=ctx.environment(OURS))
        self.env = crosstalk_workspace.colcon_env(toolchain)
        self.env["COLCON_HOME"] = str(root / "colcon-home")
        self.env.pop("COLCON_DEFAULTS_FILE", None)
        self.env.pop("PYTHONPATH", None)

    def colcon(self, build: str, verb: str, args: Sequence[str], extra: Mapping[str, str]
               ) -> tuple[float, str]:  # fmt: skip
        """``colcon VERB`` on one build: its wall seconds and its output; raise if stuck."""
        command = [
            "colcon", "--log-base", str(self.root / "log" / build), verb,
            "--base-paths", str(self.root / "src"),
            "--build-base", str(self.root / "build" / build),
            "--install-base", str(self.root / "install" / build),
            *args,
        ]  # fmt: skip
        start = time.perf_counter()
        proc = subprocess.run(
            command,
            cwd=self.root,
            env={**self.env, **extra},
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=RUN_TIMEOUT,
            check=False,
        )
        wall = time.perf_counter() - start
        if verb == "build" and proc.returncode != 0:
            raise RuntimeError(f"colcon build of {build} failed:\n{proc.stdout[-4000:]}")
        return wall, proc.stdout

    def build(self, build: str, cmake_args: Sequence[str]) -> float:
        """Build every package once for ``build`` (``plain`` or ``ours``)."""
        python = f"-DPython3_EXECUTABLE={sys.executable}"
        extra = {"COLCON_EXTENSION_BLOCKLIST": BLOCK_COORDINATOR}
        wall, _ = self.colcon(build, "build", ["--cmake-args", python, *cmake_args], extra)
        return wall

    def result(self, build: str, token: str) -> Path:
        """Where ament puts the result file of ``token``'s test."""
        package = self.package_of[token]
        return (
            self.root
            / "build"
            / build
            / package
            / "test_results"
            / package
            / (f"talker_{token}.xml")
        )

    def test(self, way: Way) -> Round:
        """One ``colcon test`` as ``way`` says, after clearing the last run's results."""
        for package in self.packages:
            shutil.rmtree(self.root / "build" / way.build / package / "test_results",
                          ignore_errors=True)  # fmt: skip
        records = self.root / "records"
        shutil.rmtree(records, ignore_errors=True)
        records.mkdir()
        extra = {"CROSSTALK_RECORD_DIR": str(records)}
        if way.coordinator:
            extra["PYTHONPATH"] = str(COORDINATOR_DIR)
        else:
            extra["COLCON_EXTENSION_BLOCKLIST"] = BLOCK_COORDINATOR
        wall, _ = self.colcon(way.build, "test", way.args, extra)
        passed = {
            token: not result_failed(self.result(way.build, token)) for token in self.package_of
        }
        heard = crosstalk_workspace.read_records(records)
        own, other = crosstalk(heard, self.package_of)
        domains = frozenset(r.domain_id or "unset" for r in heard.values())
        return Round(wall, passed, own, other, domains)


def include_path(ctx: Context) -> str:
    """What ``ros-isolated-test cmake-include`` prints: the zero-edit recipe's file."""
    proc = subprocess.run(
        [sys.executable, "-m", "ros_isolated_test", "cmake-include"],
        env=ctx.environment(OURS),
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    return proc.stdout.strip()


def _domains(rounds: Sequence[Round]) -> str:
    """Distinct domain IDs per run (median), and which when it is always the same one."""
    counts = [len(r.domains) for r in rounds]
    if not counts:
        return "-"
    values = set().union(*(r.domains for r in rounds))
    if len(values) == 1:
        (only,) = values
        return f"1 ({only})"
    return f"{median(counts):.0f} per run"


def _row(way: Way, done: Sequence[Round], total: int, sequential: float) -> tuple[str, ...]:
    """One way's row: wall time against (a), failures, what was heard, the domains."""
    wall = median([r.wall for r in done])
    failed = sum(not ok for r in done for ok in r.passed.values())
    own = sum(r.heard_own_package for r in done)
    other = sum(r.heard_other_package for r in done)
    return (
        way.label,
        f"`{' '.join(way.args)}`",
        secs(wall),
        ratio(wall, sequential),
        f"{failed} of {total * len(done)}",
        f"{own} / {other}",
        _domains(done),
    )


def _lead(rounds: Mapping[str, Sequence[Round]], total: int) -> str:
    """The sentence the README leads with: (d) against (a), in time and failures."""
    walls = {key: median([r.wall for r in done]) for key, done in rounds.items()}
    share = quotient(walls["d"], walls["a"])
    faster = "-" if math.isnan(share) or share <= 0 else f"{1 / share:.1f}x as fast"
    failed = ", ".join(
        f"({key}) {sum(not ok for r in done for ok in r.passed.values())}"
        for key, done in rounds.items()
    )
    runs = len(rounds["a"])
    return (
        f"(d) against (a): {ratio(walls['d'], walls['a'])} of the wall time ({faster}). "
        f"Tests failed, of {total * runs}: {failed}."
    )


def run(ctx: Context) -> Section:
    """Build twice, then each way interleaved: wall time, failures, crosstalk, domains."""
    n_packages, n_tests, listen = QUICK if ctx.quick else FULL
    reps = 1 if ctx.quick else 3
    packages = layout(n_packages, n_tests)
    total = n_packages * n_tests
    workspace = Workspace(ctx, generate(ctx.scratch("gain"), packages, listen), packages)
    coordinator = (COORDINATOR_DIR / "colcon_ros_domain_id_coordinator").is_dir()
    skipped = {
        w.key: why
        for w in ways(n_packages, n_tests)
        for why in (
            f"not run: no colcon-ros-domain-id-coordinator in {COORDINATOR_DIR.name}"
            if w.coordinator and not coordinator
            else "skipped in --quick"
            if w.key in QUICK_SKIPS and ctx.quick
            else "",
        )
        if why
    }
    chosen = [w for w in ways(n_packages, n_tests) if w.key not in skipped]
    builds = {"plain": (), "ours": (f"-DCMAKE_PROJECT_INCLUDE={include_path(ctx)}",)}
    built: dict[str, float] = {}
    for build, cmake_args in builds.items():
        progress(f"gain: colcon build of {n_packages} packages ({build})")
        built[build] = workspace.build(build, cmake_args)
    rounds: dict[str, list[Round]] = {w.key: [] for w in chosen}
    for rep in range(reps):
        order = chosen if rep % 2 == 0 else list(reversed(chosen))
        for way in order:
            progress(f"gain: {way.label} ({rep + 1}/{reps})")
            rounds[way.key].append(workspace.test(way))
    section = Section(
        f"14. What a user gains: {n_packages} packages x {n_tests} rclpy tests (each "
        f"listens {listen:g} s on a topic they all share), {reps} run(s) each, interleaved",
        ("run", "`colcon test` options", "wall time (median)", "/ (a)", "tests failed",
         "tests that heard one of their package / of another", "domain IDs per run"),
    )  # fmt: skip
    sequential = median([r.wall for r in rounds["a"]])
    for way in ways(n_packages, n_tests):
        if way.key in skipped:
            options = f"`{' '.join(way.args)}`"
            section.rows.append((way.label, options, skipped[way.key], "", "", "", ""))
        else:
            section.rows.append(_row(way, rounds[way.key], total, sequential))
    section.notes.append(_lead(rounds, total))
    section.notes.append(
        f"Each test is `examples/crosstalk_demo/test/token_talker.py`: an rclpy node that "
        f"publishes its token at 20 Hz on `/crosstalk`, waits to hear itself, then listens "
        f"{listen:g} s more and fails on any token not its own; registered with plain "
        f"`ament_add_test` (`TIMEOUT 60`), no RUNNER. Wall time is the whole `colcon test` "
        f"(`colcon test` of {n_packages} packages, colcon's own start included); a test "
        f"failed when its result file is missing or holds a failure. Builds, not in the wall "
        f"times: ament's runner {secs(built['plain'])}, ours {secs(built['ours'])} "
        f"(`--cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)`)."
    )
    section.notes.append(
        "colcon's coordinator (given to colcon on `PYTHONPATH` for (c) and (c'); every other "
        "run blocks it with `COLCON_EXTENSION_BLOCKLIST`) gives one ID to each package's "
        "task, so the tests of one package that run at once share it; (c') is the fastest "
        "it allows without crosstalk. "
        f"{len(os.sched_getaffinity(0))} CPUs; the times move with the machine's load."
    )
    return section


if __name__ == "__main__":
    print("run it through benches/run.py --only gain", file=sys.stderr)
    sys.exit(2)
