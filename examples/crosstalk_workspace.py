"""Build and test the crosstalk_demo package in a throwaway colcon workspace.

examples/demo.py and tests/e2e/test_example_package.py both drive colcon through these helpers,
so the demo and its test check exactly the same thing. Everything is derived from the
interpreter running this module (a virtualenv with ROS 2, ament_cmake and colcon), so no
ROS setup script has to be sourced first; a :class:`Toolchain` names another such venv (the
test suite builds the package with Jazzy's and with Kilted's).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

PACKAGE = "crosstalk_demo"
PACKAGE_DIR = Path(__file__).resolve().parent / PACKAGE
RUNNERS = ("isolated", "plain", "upstream", "extension", "off")
#: The runs as a user meets them: the package as written (no RUNNER named) in a workspace's
#: src/, a plain `colcon build` and `colcon test`, ros-isolated-test's colcon extension on
#: (installed where colcon runs) or turned off: ROS_ISOLATED_TEST_COLCON for each.
COLCON_SWITCH = {"extension": "on", "off": "off"}
DEFAULT_JOBS = 6
#: The last line of `colcon test` with the extension on, naming the page it wrote.
_PAGE = re.compile(r"^ros-isolated-test: .*; page: (.+)$", re.MULTILINE)

_SUMMARY = re.compile(
    r"^Summary: (\d+) tests?, (\d+) errors?, (\d+) failures?, (\d+) skipped", re.MULTILINE
)
_ADD_TEST = re.compile(r"^add_test\(\[=\[(?P<name>[^\]]+)\]=\] (?P<args>.*)\)$", re.MULTILINE)
_QUOTED = re.compile(r'"((?:[^"\\]|\\.)*)"')


class WorkspaceError(RuntimeError):
    """A colcon step failed in a way that leaves nothing to report on (not a test failure)."""


@dataclass(frozen=True)
class Toolchain:
    """The venv that builds and tests the package: its Python and the environment to start from.

    The default is the interpreter running this module and this process's environment, read
    at call time. Another distro's venv needs its Python, its prefix, and a base environment
    as its sourced setup would give (its libraries and AMENT_PREFIX_PATH, none of ours).
    """

    python: str = sys.executable
    prefix: str = sys.prefix
    base_env: Mapping[str, str] | None = field(default=None, compare=False)


THIS_PYTHON = Toolchain()


def colcon_env(toolchain: Toolchain = THIS_PYTHON) -> dict[str, str]:
    """Return the environment for colcon, CMake, ctest and the tests.

    CMake finds ament_cmake under the interpreter's prefix (share/ament_cmake/cmake) only
    if that prefix is on CMAKE_PREFIX_PATH or its bin/ is on PATH; we set both, in front,
    so a ROS install sourced in the user's shell cannot shadow it. PATH also provides
    colcon and ros-isolated-test. ROS_DOMAIN_ID goes: the isolated runner refuses a preset
    one, and the control must run on the default domain like an unconfigured machine.
    DISABLE_ROS_ISOLATION goes too, or the isolated run would not isolate.
    """
    env = dict(os.environ if toolchain.base_env is None else toolchain.base_env)
    prefix = toolchain.prefix
    env["PATH"] = os.pathsep.join(p for p in (str(Path(prefix) / "bin"), env.get("PATH")) if p)
    env["CMAKE_PREFIX_PATH"] = os.pathsep.join(
        p for p in (prefix, env.get("CMAKE_PREFIX_PATH")) if p
    )
    for name in ("ROS_DOMAIN_ID", "DISABLE_ROS_ISOLATION"):
        env.pop(name, None)
    return env


def isolated_runner_problem(toolchain: Toolchain = THIS_PYTHON) -> str | None:
    """Say why `ros-isolated-test runner-path` cannot give a runner, or None if it can."""
    try:
        proc = subprocess.run(
            ["ros-isolated-test", "runner-path"],
            env=colcon_env(toolchain),
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    except FileNotFoundError:
        return "the ros-isolated-test command is not installed"
    path = proc.stdout.strip()
    if proc.returncode != 0:
        return f"`ros-isolated-test runner-path` exited {proc.returncode}: {proc.stderr.strip()}"
    if not Path(path).is_file():
        return f"`ros-isolated-test runner-path` printed {path!r}, which is not a file"
    return None


def extension_problem(toolchain: Toolchain = THIS_PYTHON) -> str | None:
    """Say why colcon would not load ros-isolated-test's colcon extension, or None if it would.

    What a user checks: `colcon extensions` lists it (``ros-isolated-test status`` says
    the same for the colcon on PATH).
    """
    try:
        code, output = _colcon(
            ["--log-base", os.devnull, "extensions"], cwd=PACKAGE_DIR, toolchain=toolchain
        )
    except FileNotFoundError:
        return "no colcon on PATH"
    if code != 0:
        return f"`colcon extensions` exited {code}:\n{output}"
    if "ros_isolated_test:" not in output:
        return (
            "`colcon extensions` does not list ros_isolated_test: install ros-isolated-test "
            "into colcon's Python (see docs/install.md)"
        )
    return None


@dataclass(frozen=True)
class Record:
    """What one token_talker process wrote about itself (CROSSTALK_RECORD_DIR/<token>.json)."""

    token: str
    domain_id: str | None
    pid: int
    start: float
    end: float
    own_received: int
    foreign: dict[str, int]
    passed: bool


@dataclass(frozen=True)
class Case:
    """One registered ctest test: its name, its token, and its record if it wrote one."""

    name: str
    token: str
    record: Record | None


@dataclass(frozen=True)
class ResultSummary:
    """The totals line of `colcon test-result --all` and that command's exit status."""

    line: str
    tests: int
    errors: int
    failures: int
    skipped: int
    returncode: int


@dataclass(frozen=True)
class Run:
    """Everything one build-and-test of the package under one runner produced."""

    runner: str
    runner_path: str
    base: Path
    build_seconds: float
    test_seconds: float
    test_output: str
    cases: tuple[Case, ...]
    result: ResultSummary

    @property
    def page(self) -> Path | None:
        """The page the colcon extension's last line names (None: it named none)."""
        found = _PAGE.findall(self.test_output)
        return (self.base / found[-1]) if found else None

    @property
    def domain_ids(self) -> list[str | None]:
        return [c.record.domain_id if c.record else None for c in self.cases]

    @property
    def all_passed(self) -> bool:
        return all(c.record is not None and c.record.passed for c in self.cases)


def _colcon(
    args: list[str],
    cwd: Path,
    extra_env: dict[str, str] | None = None,
    toolchain: Toolchain = THIS_PYTHON,
) -> tuple[int, str]:
    env = colcon_env(toolchain)
    env.update(extra_env or {})
    proc = subprocess.run(
        ["colcon", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        check=False,
    )
    return proc.returncode, proc.stdout


def _common(base: Path) -> list[str]:
    return [
        "--base-paths", str(PACKAGE_DIR),
        "--build-base", str(base / "build"),
        "--install-base", str(base / "install"),
    ]  # fmt: skip


def build(workspace: Path, runner: str, toolchain: Toolchain = THIS_PYTHON) -> Path:
    """Configure and build the package for one runner in <workspace>/<runner>; return that dir.

    Each runner gets its own build dir because the runner is baked into CTestTestfile.cmake
    at configure time. The colcon extension's runs (:data:`COLCON_SWITCH`) are a workspace
    as a user has one: the package copied into its src/, `colcon build` run there, no flag.
    """
    if runner not in RUNNERS:
        raise ValueError(f"runner must be one of {RUNNERS}, not {runner!r}")
    base = workspace / runner
    base.mkdir(parents=True, exist_ok=True)
    if runner in COLCON_SWITCH:
        shutil.copytree(PACKAGE_DIR, base / "src" / PACKAGE, dirs_exist_ok=True)
        code, output = _colcon(["build"], cwd=base, extra_env=_switch(runner), toolchain=toolchain)
        if code != 0:
            raise WorkspaceError(f"colcon build ({runner}) failed:\n{output}")
        return base
    cmake_args = [f"-DCROSSTALK_RUNNER={runner}", f"-DPython3_EXECUTABLE={toolchain.python}"]
    code, output = _colcon(
        ["--log-base", str(base / "log"), "build", *_common(base), "--cmake-args", *cmake_args],
        cwd=workspace,
        toolchain=toolchain,
    )
    if code != 0:
        raise WorkspaceError(f"colcon build with CROSSTALK_RUNNER={runner} failed:\n{output}")
    return base


def _switch(runner: str) -> dict[str, str]:
    """ROS_ISOLATED_TEST_COLCON for a run of the colcon extension (none for the others)."""
    return {"ROS_ISOLATED_TEST_COLCON": COLCON_SWITCH[runner]} if runner in COLCON_SWITCH else {}


def registered_tests(base: Path) -> tuple[str, dict[str, str]]:
    """Read the runner path and each test's token from the CTestTestfile.cmake CMake wrote.

    Reading what ctest will actually run, rather than repeating CMakeLists.txt, keeps the
    report honest about which runner wrapped the tests.
    """
    text = (base / "build" / PACKAGE / "CTestTestfile.cmake").read_text()
    runner_path = ""
    tokens: dict[str, str] = {}
    for match in _ADD_TEST.finditer(text):
        args = _QUOTED.findall(match["args"])
        runner_path = args[args.index("-u") + 1]
        tokens[match["name"]] = args[-1]
    if not tokens:
        raise WorkspaceError(f"no tests registered in {base / 'build' / PACKAGE}")
    return runner_path, tokens


def read_records(record_dir: Path) -> dict[str, Record]:
    """Load every <token>.json the test processes wrote, keyed by token."""
    records: dict[str, Record] = {}
    for path in sorted(record_dir.glob("*.json")):
        data = json.loads(path.read_text())
        records[data["token"]] = Record(**data)
    return records


def result_summary(base: Path, toolchain: Toolchain = THIS_PYTHON) -> ResultSummary:
    """Run `colcon test-result --all` on the build dir and parse its totals line."""
    code, output = _colcon(
        ["--log-base", str(base / "log"), "test-result", "--test-result-base",
         str(base / "build"), "--all"],
        cwd=base,
        toolchain=toolchain,
    )  # fmt: skip
    matches = list(_SUMMARY.finditer(output))
    if not matches:
        raise WorkspaceError(f"no summary line in `colcon test-result` output:\n{output}")
    match = matches[-1]  # the totals line comes last, after one line per result file
    tests, errors, failures, skipped = (int(g) for g in match.groups())
    return ResultSummary(match[0], tests, errors, failures, skipped, code)


def run(
    workspace: Path, runner: str, jobs: int = DEFAULT_JOBS, toolchain: Toolchain = THIS_PYTHON
) -> Run:
    """Build, run all tests at once with `colcon test --ctest-args -jN`, and collect results."""
    started = time.monotonic()
    base = build(workspace, runner, toolchain)
    built = time.monotonic()
    record_dir = base / "records"
    record_dir.mkdir(exist_ok=True)
    for old in record_dir.glob("*.json"):
        old.unlink()
    test_args = ["--log-base", str(base / "log"), "test", *_common(base)]
    if runner in COLCON_SWITCH:
        test_args = ["test"]  # in the workspace, as a user types it
    _, test_output = _colcon(
        [*test_args, "--ctest-args", f"-j{jobs}"],
        cwd=base if runner in COLCON_SWITCH else workspace,
        extra_env={"CROSSTALK_RECORD_DIR": str(record_dir), **_switch(runner)},
        toolchain=toolchain,
    )
    tested = time.monotonic()
    runner_path, tokens = registered_tests(base)
    records = read_records(record_dir)
    cases = tuple(Case(name, token, records.get(token)) for name, token in sorted(tokens.items()))
    return Run(
        runner=runner,
        runner_path=runner_path,
        base=base,
        build_seconds=built - started,
        test_seconds=tested - built,
        test_output=test_output,
        cases=cases,
        result=result_summary(base, toolchain),
    )
