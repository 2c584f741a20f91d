"""Runs of launch files under pytest, colcon or ctest, and what each left behind.

For the tests of the pytest plugin's launch modules (tests/unit/pytest_plugin/test_launch_*,
tests/e2e/test_launch_*): the launch tier's own environment (helpers/launch_env.py: real
launch_testing from the outside tier's vendored Jazzy sources), colcon's environment
around it with a lock dir and pool of the run's own, and a run read back: its output, the
launch log every launch and case writes (helpers/launch_files.py), the talkers' records
and pytest's own result files.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from lxml import etree

from helpers import capabilities, launch_env, launch_files
from helpers.commands import HUNG, POLICY_VARS, normalise
from helpers.domains import free_ids
from helpers.results import CaseResult, load_result
from helpers.workspace import crosstalk_workspace

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Record, ResultSummary

#: Only stops a hung colcon; no verdict depends on it.
COLCON_HUNG = HUNG * 4


def launch_python() -> Path:
    """The launch tier's own interpreter (built once, then kept in ``.venv-launch/``)."""
    capabilities.require(capabilities.OUTSIDE, capabilities.CTEST, capabilities.TOMLLIB)
    return launch_env.ensure()


def launch_environment(python: Path, root: Path, pool: int) -> dict[str, str]:
    """colcon's environment with the launch prefix first, a lock dir and pool of its own."""
    ws = crosstalk_workspace()
    prefix = python.parents[1]
    toolchain = ws.Toolchain(python=str(python), prefix=str(prefix))
    env = {k: v for k, v in ws.colcon_env(toolchain).items() if k not in POLICY_VARS}
    env.pop("LAUNCH_CASES_TOKEN", None)
    (root / "locks").mkdir(parents=True, exist_ok=True)
    env["ROS_ISOLATED_TEST_LOCK_DIR"] = str(root / "locks")
    env["ROS_ISOLATED_TEST_DOMAINS"] = ",".join(map(str, free_ids(pool)))
    return env


def ament_python_package(root: Path, name: str) -> Path:
    """An empty ament_python package at ``root/name`` (its own pytest.ini), for test files."""
    package = root / name
    (package / "test").mkdir(parents=True)
    (package / "pytest.ini").write_text("[pytest]\n")
    (package / "package.xml").write_text(
        launch_files.PACKAGE_XML.format(name=name, depends="", build_type="ament_python")
    )
    return package


@dataclass(frozen=True)
class Run:
    """What one run of launch files left: output, logs, records and result files."""

    output: str
    returncode: int
    log: list[list[str]]  # helpers.launch_files.read_log
    records: dict[str, Record]  # each talker's own record, by token
    junit: dict[str, Path]  # pytest's own result files, by name

    def launches(self, token: str) -> list[list[str]]:
        return [line for line in self.log if line[:2] == ["launch", token]]

    def cases(self, token: str) -> list[list[str]]:
        return [line for line in self.log if line[:2] == ["case", token]]


def run_launches(
    root: Path, env: Mapping[str, str], argv: list[str], junit: dict[str, Path], cwd: Path
) -> Run:
    """``argv`` with a fresh log and record folder; what it left behind."""
    log, records = root / "launch.log", root / "records"
    log.unlink(missing_ok=True)
    records.mkdir(exist_ok=True)
    for old in [*records.glob("*.json"), *junit.values()]:
        old.unlink(missing_ok=True)
    done = subprocess.run(
        argv,
        cwd=cwd,
        env={**env, "LAUNCH_CASES_LOG": str(log), "CROSSTALK_RECORD_DIR": str(records)},
        capture_output=True,
        text=True,
        timeout=COLCON_HUNG,
        check=False,
    )
    return Run(
        output=done.stdout + done.stderr,
        returncode=done.returncode,
        log=launch_files.read_log(log),
        records=crosstalk_workspace().read_records(records),
        junit=junit,
    )


def raw_cases(path: Path) -> dict[str, str]:
    """pytest's own result file, as colcon test-result reads it: outcome by case name."""
    assert path.is_file(), f"no result file at {path}"
    outcomes: dict[str, str] = {}
    for case in etree.parse(str(path)).getroot().iter("testcase"):
        kinds = [child.tag for child in case if child.tag in ("failure", "error", "skipped")]
        outcomes[case.get("name", "")] = kinds[0] if kinds else "passed"
    return outcomes


def canonical(
    source: Path, package: str, env: Mapping[str, str], into: Path
) -> tuple[CaseResult, ...]:
    """The cases of ``source`` made canonical by ``ros-isolated-test normalise`` (in ``into``)."""
    into.mkdir(parents=True, exist_ok=True)
    output = into / f"{package}.xml"  # not beside the source: colcon test-result reads those
    normalise(source, output, env, package)
    return load_result(output).cases


@dataclass(frozen=True)
class Workspace:
    """ament_python packages of launch files, tested at once by the launch environment's colcon."""

    root: Path
    env: dict[str, str]
    colcon: list[str]  # the launch environment's colcon with this workspace's folders
    packages: Mapping[str, str]  # each package's name, by its talker's token

    def test(self, *extra: str) -> tuple[Run, ResultSummary]:
        """``colcon test`` of every package at once, and colcon test-result's totals."""
        junit = {token: self.root / "build" / name / "pytest.xml"
                 for token, name in self.packages.items()}  # fmt: skip
        workers = str(len(self.packages))
        argv = [*self.colcon, "test", *self.paths, "--parallel-workers", workers, *extra]
        run = run_launches(self.root, self.env, argv, junit, self.root)
        ws = crosstalk_workspace()
        prefix = Path(self.colcon[0]).parents[1]
        toolchain = ws.Toolchain(python=str(prefix / "bin" / "python"), prefix=str(prefix))
        return run, ws.result_summary(self.root, toolchain)

    @property
    def paths(self) -> list[str]:
        return ["--base-paths", str(self.root / "src"), "--build-base", str(self.root / "build"),
                "--install-base", str(self.root / "install")]  # fmt: skip

    def talkers(self, run: Run) -> list[Record]:
        """Each package's talker record, in the order of :attr:`packages`; all must be there."""
        missing = sorted(set(self.packages) - set(run.records))
        assert not missing, f"no talker record from {missing}:\n{run.output}"
        return [run.records[token] for token in self.packages]


def build_workspace(
    root: Path, packages: Mapping[str, str], write: Callable[[Path, str, str], object]
) -> Workspace:
    """``packages`` written by ``write(src, name, token)`` and built once by colcon."""
    python = launch_python()
    for token, name in packages.items():
        write(root / "src", name, token)
    env = launch_environment(python, root, pool=len(packages))
    colcon = [str(python.parent / "colcon"), "--log-base", str(root / "log")]
    workspace = Workspace(root, env, colcon, packages)
    build = subprocess.run(
        [*colcon, "build", *workspace.paths], cwd=root, env=env, capture_output=True,
        text=True, timeout=COLCON_HUNG, check=False,
    )  # fmt: skip
    assert build.returncode == 0, f"colcon build failed:\n{build.stdout}{build.stderr}"
    return workspace
