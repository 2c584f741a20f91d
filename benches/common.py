"""What every benchmark shares: the runners, their environments, timing, statistics, tables.

Runners are compared in pairs that share an interpreter and an environment, so that the
only difference measured is the runner itself: ours against Jazzy's upstream under the
Jazzy venv (the one running the benchmarks), and ours against Kilted's upstream under
the Kilted venv (``.venv-kilted``, when scripts/setup.sh made it). Everything a run
leaves behind goes into one temporary directory.
"""

from __future__ import annotations

import contextlib
import math
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

REPO = Path(__file__).resolve().parent.parent
#: Every colcon a benchmark starts builds the way its row says (the include passed, or
#: nothing of ours): ros-isolated-test's colcon extension, installed in this venv, stays off.
os.environ.setdefault("ROS_ISOLATED_TEST_COLCON", "off")
#: Ours and Jazzy's upstream, both under the Jazzy venv (the interpreter running this).
OURS = "ours"
UPSTREAM = "upstream"
#: Ours and Kilted's upstream, both under the Kilted venv.
OURS_KILTED = "ours-kilted"
KILTED = "kilted"
#: The runners every benchmark that predates Kilted compares: the Jazzy pair.
RUNNERS = (OURS, UPSTREAM)
#: Like with like: each (ours, upstream) pair shares one interpreter and environment.
PAIRS = ((OURS, UPSTREAM), (OURS_KILTED, KILTED))
LABELS = {
    OURS: "ours",
    UPSTREAM: "Jazzy upstream",
    OURS_KILTED: "ours (Kilted venv)",
    KILTED: "Kilted upstream",
}
#: Where scripts/setup.sh puts the Kilted venv.
KILTED_VENV = REPO / ".venv-kilted"
#: Path lists a sourced ROS setup extends; entries of the other venv are taken out.
_PATH_LISTS = ("PATH", "AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH", "LD_LIBRARY_PATH", "PYTHONPATH")
#: Variables that change what either runner decides; the benchmarks set them explicitly.
POLICY_VARS = (
    "ROS_DOMAIN_ID",
    "DISABLE_ROS_ISOLATION",
    "ROS_ISOLATED_TEST_DOMAINS",
    "ROS_ISOLATED_TEST_LOCK_DIR",
    "ROS_ISOLATED_TEST_WAIT_TIMEOUT",
)
#: Set by the ROS wheels' .pth hook once it has re-executed the interpreter.
BOOTSTRAP_MARK = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"
PACKAGE = "bench"


def upstream_runner_path() -> Path:
    """ament_cmake_ros's run_test_isolated.py under this interpreter's prefix."""
    return Path(sys.prefix) / "share" / "ament_cmake_ros" / "cmake" / "run_test_isolated.py"


def kilted_runner_path(prefix: Path = KILTED_VENV) -> Path:
    """Kilted's run_test_isolated.py (it puts run_rmw_isolated before the command)."""
    return prefix / "share" / "ament_cmake_ros" / "cmake" / "run_test_isolated.py"


def ours_runner_path(python: str = sys.executable, env: Mapping[str, str] | None = None) -> Path:
    """What ``ros-isolated-test runner-path`` prints, asked of ``python``."""
    proc = subprocess.run(
        [python, "-m", "ros_isolated_test", "runner-path"],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
        env=None if env is None else dict(env),
    )
    return Path(proc.stdout.strip())


def _within(path: str, roots: Sequence[Path]) -> bool:
    """Whether ``path`` lies in one of ``roots`` (as written or with links resolved)."""
    candidates = {Path(path)}
    with contextlib.suppress(OSError):
        candidates.add(Path(path).resolve())
    return any(c == r or r in c.parents for c in candidates for r in roots)


def venv_environment(base: Mapping[str, str], prefix: Path, other: Path) -> dict[str, str]:
    """``base`` as a sourced setup of the venv ``prefix`` gives it, with no trace of ``other``.

    The benchmarks run in the Jazzy venv, whose entries leak into every child's
    environment; the wheels' start-up hook keeps LD_LIBRARY_PATH in a set (random
    order), so a Kilted process could load Jazzy's libraries. The bootstrap mark is set,
    as under a colcon of that venv: the library path is already right.
    """
    roots = [root for venv in (prefix, other) for root in {venv, venv.resolve()}]
    env = dict(base)
    for name in _PATH_LISTS:
        kept = [p for p in base.get(name, "").split(os.pathsep) if p and not _within(p, roots)]
        env[name] = os.pathsep.join(kept)
    site = sorted((prefix / "lib").glob("python3.*/site-packages"))
    libs = [str(d.resolve()) for s in site for d in sorted(s.glob("ros_*.libs")) if d.is_dir()]
    own = {
        "PATH": [str(prefix / "bin")],
        "AMENT_PREFIX_PATH": [str(prefix)],
        "CMAKE_PREFIX_PATH": [str(prefix)],
        "LD_LIBRARY_PATH": [str(prefix / "lib"), *libs],
        "PYTHONPATH": [],
    }
    for name, first in own.items():
        joined = os.pathsep.join([*first, *filter(None, [env[name]])])
        if joined:
            env[name] = joined
        else:
            env.pop(name, None)
    env[BOOTSTRAP_MARK] = "1"
    return env


def kilted_missing(prefix: Path = KILTED_VENV) -> str | None:
    """Why the Kilted pair cannot run here, or None."""
    if not (prefix / "bin" / "python").exists():
        return f"no Kilted venv at {prefix.name} (scripts/setup.sh makes it)"
    if not kilted_runner_path(prefix).is_file():
        return f"{prefix.name} has no ament_cmake_ros runner (scripts/setup.sh installs it)"
    return None


def base_environment(work: Path) -> dict[str, str]:
    """The environment both runners get: no domain policy, a private lock directory.

    ``PYTHONDONTWRITEBYTECODE`` is dropped so that modules are imported from cached
    bytecode, as they are from an installed package; otherwise every runner start would
    compile its modules from source and the benchmark would measure the compiler.
    """
    env = {key: value for key, value in os.environ.items() if key not in POLICY_VARS}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["ROS_ISOLATED_TEST_LOCK_DIR"] = str(work / "locks")
    bin_dir = str(Path(sys.executable).parent)
    env["PATH"] = os.pathsep.join(p for p in (bin_dir, env.get("PATH", "")) if p)
    return env


@dataclass(frozen=True)
class Context:
    """Where the runners are, which environment they get, and how long to measure.

    ``python`` and ``env`` are the Jazzy venv's; ``pythons`` and ``envs`` give each
    runner's own (the Kilted pair's are the Kilted venv's). Runners absent here (no
    Kilted venv) are left out of every table, which says so.
    """

    python: str
    runners: Mapping[str, Path]
    work: Path
    env: Mapping[str, str]
    quick: bool
    pythons: Mapping[str, str] = field(default_factory=dict)
    envs: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    missing: Mapping[str, str] = field(default_factory=dict)

    def python_of(self, runner: str) -> str:
        """The interpreter ``runner`` is started with (and every process of its side)."""
        return self.pythons.get(runner, self.python)

    def pairs(self) -> list[tuple[str, str]]:
        """The (ours, upstream) pairs both of whose runners are here."""
        return [pair for pair in PAIRS if all(r in self.runners for r in pair)]

    def all_runners(self) -> tuple[str, ...]:
        """Every runner present, pair by pair."""
        return tuple(r for pair in self.pairs() for r in pair)

    def runner_command(
        self, runner: str, result: Path, command: Sequence[str], generate: bool = True
    ) -> list[str]:
        """Exactly what ctest runs: ``python -u RUNNER RESULT --package-name P ... --command``."""
        flags = ["--generate-result-on-success"] if generate else []
        return [
            self.python_of(runner),
            "-u",
            str(self.runners[runner]),
            str(result),
            "--package-name",
            PACKAGE,
            *flags,
            "--command",
            *command,
        ]

    def start_runners(
        self, runner: str, results: Sequence[Path], command: Sequence[str], env: Mapping[str, str]
    ) -> list[subprocess.Popen[bytes]]:
        """One ``runner`` per result path, all started at once, as ``ctest -j`` starts them."""
        return [
            subprocess.Popen(
                self.runner_command(runner, result, command),
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.STDOUT,
            )
            for result in results
        ]

    def pair_section(self, title: str) -> tuple[list[tuple[str, str]], Section]:
        """The pairs here, and a table with ours, upstream and their ratio for each pair."""
        pairs = self.pairs()
        header = [""]
        for ours, upstream in pairs:
            header += [LABELS[ours], LABELS[upstream], f"ours / {LABELS[upstream].split()[0]}"]
        header.append("target")
        return pairs, Section(title, header)

    def environment(self, runner: str = OURS, **extra: str) -> dict[str, str]:
        """``runner``'s environment (its venv's; shared within a pair) plus ``extra``."""
        env = dict(self.envs.get(runner, self.env))
        env.update(extra)
        return env

    def scratch(self, name: str) -> Path:
        """A fresh directory under the work directory."""
        path = self.work / name
        path.mkdir(parents=True, exist_ok=True)
        return path


@dataclass(frozen=True)
class Timed:
    """One finished process: wall time, exit code, peak RSS of it and its descendants."""

    seconds: float
    returncode: int
    max_rss_kib: int


def run_timed(
    command: Sequence[str],
    env: Mapping[str, str],
    stdout: int | IO[bytes] | None = subprocess.DEVNULL,
    cwd: Path | None = None,
) -> Timed:
    """Run to completion; wall time from just before the fork to the reaping wait4.

    With ``stdout=subprocess.PIPE`` the output is read and thrown away as it comes, in
    1 MiB reads, as ctest reads a test's output from a pipe. wait4's rusage gives
    ru_maxrss for the process itself, or for a descendant it waited for if that one grew
    bigger: here that is the runner, whose test command (a shell, ``yes``, ``head``,
    ``true``) stays at a few MB.
    """
    start = time.perf_counter()
    proc = subprocess.Popen(
        list(command),
        env=dict(env),
        stdin=subprocess.DEVNULL,
        stdout=stdout,
        stderr=subprocess.STDOUT,
        cwd=cwd,
    )
    if proc.stdout is not None:
        fd = proc.stdout.fileno()
        while os.read(fd, 1 << 20):
            pass
        proc.stdout.close()
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    return Timed(seconds, proc.returncode, int(usage.ru_maxrss))


def timed_ctest(build_dir: Path, jobs: int, env: Mapping[str, str]) -> tuple[float, str]:
    """``ctest --test-dir BUILD -jN``: its wall seconds and its merged output."""
    start = time.perf_counter()
    proc = subprocess.run(
        ["ctest", "--test-dir", str(build_dir), f"-j{jobs}"],
        env=dict(env),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        check=False,
    )
    return time.perf_counter() - start, proc.stdout


def interleaved(reps: int, runners: Sequence[str] = RUNNERS) -> Iterator[tuple[int, str]]:
    """(repetition, runner) pairs, the order flipped every repetition (ABBA...).

    Alternating which runner goes first cancels slow drift in the machine's load.
    """
    for rep in range(reps):
        order = runners if rep % 2 == 0 else tuple(reversed(runners))
        for runner in order:
            yield rep, runner


def median(values: Sequence[float]) -> float:
    """Median; NaN for no values (shown as a dash)."""
    return statistics.median(values) if values else float("nan")


def percentile(values: Sequence[float], pct: float) -> float:
    """Linear-interpolated percentile (``pct`` in 0..100); NaN for no values."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    rank = (len(ordered) - 1) * pct / 100.0
    low = int(rank)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (rank - low)


def ms(seconds: float) -> str:
    """Seconds shown as milliseconds."""
    if math.isnan(seconds):
        return "-"
    return f"{seconds * 1000:.0f} ms" if seconds >= 0.01 else f"{seconds * 1000:.1f} ms"


def secs(seconds: float) -> str:
    """Seconds shown as seconds."""
    if math.isnan(seconds):
        return "-"
    return f"{seconds:.2f} s"


def ratio(ours: float, upstream: float) -> str:
    """ours / upstream, the number the table is about."""
    if math.isnan(ours) or math.isnan(upstream) or upstream <= 0:
        return "-"
    value = ours / upstream
    return f"{value:.2f}" if value < 10 else f"{value:.0f}"


def verdict(met: bool | None) -> str:
    """A target's state as the tables show it (None: not measured)."""
    if met is None:
        return "not measured"
    return "met" if met else "**NOT met**"


def at_most(value: float, limit: float) -> bool | None:
    """``value <= limit``, or None when ``value`` is missing (NaN)."""
    return None if math.isnan(value) else value <= limit


def quotient(numerator: float, denominator: float) -> float:
    """numerator / denominator, NaN when either is missing or the denominator is not > 0."""
    if math.isnan(numerator) or math.isnan(denominator) or denominator <= 0:
        return float("nan")
    return numerator / denominator


def startup_seconds(env: Mapping[str, str], reps: int, reexec: bool) -> float:
    """Median wall time of ``python -u -c pass`` in this venv.

    ``reexec=True`` clears the ROS wheels' bootstrap mark so the interpreter re-executes
    itself once, as from a fresh shell; without it the mark is inherited, as it is by
    every process under colcon (colcon is a Python of this venv).
    """
    run_env = dict(env)
    if reexec:
        run_env.pop(BOOTSTRAP_MARK, None)
    else:
        run_env[BOOTSTRAP_MARK] = "1"
    times = [run_timed([sys.executable, "-u", "-c", "pass"], run_env).seconds for _ in range(reps)]
    return median(times)


def parse_importtime(lines: Sequence[str]) -> list[tuple[int, str, int, int]]:
    """Parse ``-X importtime`` lines into (level, module, self µs, cumulative µs).

    A line reads ``import time: SELF | CUMULATIVE | <two spaces per level>NAME``.
    """
    parsed = []
    for line in lines:
        if not line.startswith("import time:") or "imported package" in line:
            continue
        fields = line.split(":", 1)[1].split("|")
        if len(fields) != 3:
            continue
        self_us, cumulative, name = fields
        level = (len(name) - len(name.lstrip(" ")) - 1) // 2
        parsed.append((level, name.strip(), int(self_us), int(cumulative)))
    return parsed


@dataclass
class Section:
    """One benchmark's part of the report: a table, then notes under it."""

    title: str
    header: Sequence[str]
    rows: list[Sequence[str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def render(self) -> str:
        """Markdown, so the output can be pasted into docs/performance.md as it is."""
        lines = [f"### {self.title}", ""]
        lines.append("| " + " | ".join(self.header) + " |")
        lines.append("|" + "|".join("---" for _ in self.header) + "|")
        lines.extend("| " + " | ".join(row) + " |" for row in self.rows)
        if self.notes:
            lines.append("")
            lines.extend(self.notes)
        return "\n".join(lines)


def progress(message: str) -> None:
    """Say what runs now, on stderr, so the table on stdout stays clean."""
    print(f"[bench] {message}", file=sys.stderr, flush=True)
