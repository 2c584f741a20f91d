"""examples/isolated_all built with real colcon, finding ros_isolated_test from PATH alone.

pip installs the CMake package as ``<prefix>/share/ros_isolated_test/cmake`` beside
``<prefix>/bin/ros-isolated-test``; an editable install (this suite's .venv) does not copy
data files. So the build gets a prefix of that exact layout in its temp dir, whose bin/
holds the venv's command and whose share/ holds the checkout's files, first on PATH, and
no CMAKE_PREFIX_PATH at all: what CMake finds, it finds the way a user's CMake would.
Each configuration is built once (the module-scoped fixture), then tested as often as
needed.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path
from typing import TYPE_CHECKING

from helpers.commands import REPO
from helpers.workspace import crosstalk_workspace

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Record, ResultSummary

PACKAGE = "isolated_all"
PACKAGE_DIR = REPO / "examples" / PACKAGE
CMAKE_FILES = REPO / "ros_isolated_test" / "cmake"
#: A test's name is bracketed (``[=[name]=]``) under policy CMP0110 (CMake 3.19), bare before.
_ADD_TEST = re.compile(
    r"^add_test\((?:\[=\[(?P<bracketed>[^\]]+)\]=\]|(?P<bare>[^ \[]+)) (?P<args>.*)\)$",
    re.MULTILINE,
)
_QUOTED = re.compile(r'"((?:[^"\\]|\\.)*)"')


def installed_prefix(root: Path) -> Path:
    """A prefix laid out as pip installs ros-isolated-test: bin/ and share/<name>/cmake."""
    prefix = root / "prefix"
    (prefix / "bin").mkdir(parents=True, exist_ok=True)
    (prefix / "share" / "ros_isolated_test").mkdir(parents=True, exist_ok=True)
    command = shutil.which("ros-isolated-test", path=str(Path(sys.executable).parent))
    assert command is not None, "ros-isolated-test is not installed beside this Python"
    for link, target in (
        (prefix / "bin" / "ros-isolated-test", Path(command)),
        (prefix / "share" / "ros_isolated_test" / "cmake", CMAKE_FILES),
    ):
        if not link.is_symlink():
            link.symlink_to(target)
    return prefix


def runners_of(ctest_file: Path) -> dict[str, str]:
    """Each test's RUNNER script in a CTestTestfile.cmake of ament_add_test tests."""
    runners: dict[str, str] = {}
    for match in _ADD_TEST.finditer(ctest_file.read_text()):
        args = _QUOTED.findall(match["args"])
        runners[match["bracketed"] or match["bare"]] = args[args.index("-u") + 1]
    return runners


def build_wheel(root: Path) -> Path:
    """A real wheel of the project in ``root/dist``, built from a copy (the checkout is never
    written)."""
    source = root / "src"
    source.mkdir(parents=True)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    shutil.copytree(
        REPO / "ros_isolated_test",
        source / "ros_isolated_test",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--disable-pip-version-check",
         "-q", "-w", str(root / "dist"), str(source)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, f"pip wheel failed:\n{done.stdout}{done.stderr}"
    (built,) = (root / "dist").glob("ros_isolated_test-*.whl")
    return built


def install_wheel(wheel: Path, prefix: Path) -> str:
    """``pip install --prefix`` of ``wheel`` as a user does, for each wheel test: its site dir."""
    done = subprocess.run(
        # --ignore-installed: without it pip uninstalls this suite's own (editable) install
        # from .venv before installing into the prefix.
        [sys.executable, "-m", "pip", "install", "--no-deps", "--disable-pip-version-check",
         "-q", "--ignore-installed", "--prefix", str(prefix), str(wheel)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, f"pip install failed:\n{done.stdout}{done.stderr}"
    return sysconfig.get_path("purelib", vars={"base": str(prefix), "platbase": str(prefix)})


def path_only_env(prefix: Path) -> dict[str, str]:
    """colcon's environment with ``prefix/bin`` first on PATH and no CMAKE_PREFIX_PATH."""
    env: dict[str, str] = crosstalk_workspace().colcon_env()
    env.pop("CMAKE_PREFIX_PATH", None)
    env["PATH"] = os.pathsep.join((str(prefix / "bin"), env["PATH"]))
    return env


class PackageBuild:
    """One configuration of examples/isolated_all, built in ``<root>/<name>``."""

    def __init__(self, root: Path, name: str, cmake_args: list[str]) -> None:
        self.base = root / name
        self.env = path_only_env(installed_prefix(root))
        self.records = self.base / "records"
        self.output = self._colcon(
            "build", "--cmake-args", f"-DPython3_EXECUTABLE={sys.executable}", *cmake_args
        )

    @property
    def build_dir(self) -> Path:
        return self.base / "build" / PACKAGE

    @property
    def results_dir(self) -> Path:
        return self.build_dir / "test_results" / PACKAGE

    def _colcon(self, verb: str, *args: str, check: bool = True) -> str:
        common = [
            "--base-paths", str(PACKAGE_DIR),
            "--build-base", str(self.base / "build"),
            "--install-base", str(self.base / "install"),
        ]  # fmt: skip
        self.base.mkdir(parents=True, exist_ok=True)
        proc = subprocess.run(
            ["colcon", "--log-base", str(self.base / "log"), verb, *common, *args],
            cwd=self.base,
            env={**self.env, "CROSSTALK_RECORD_DIR": str(self.records)},
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            check=False,
        )
        if check and proc.returncode != 0:
            raise AssertionError(f"colcon {verb} failed:\n{proc.stdout}")
        return proc.stdout

    def test(self, jobs: int = 6) -> str:
        """``colcon test --ctest-args -jJOBS`` after clearing the last run's results."""
        for stale in self.results_dir.glob("*.xml"):
            stale.unlink()
        self.records.mkdir(parents=True, exist_ok=True)
        for stale in self.records.glob("*.json"):
            stale.unlink()
        return self._colcon("test", "--ctest-args", f"-j{jobs}", check=False)

    def records_by_token(self) -> dict[str, Record]:
        records: dict[str, Record] = crosstalk_workspace().read_records(self.records)
        return records

    def result_summary(self) -> ResultSummary:
        summary: ResultSummary = crosstalk_workspace().result_summary(self.base)
        return summary

    def runners(self) -> dict[str, str]:
        """Each registered test's RUNNER script, read from the CTestTestfile.cmake CMake wrote."""
        return runners_of(self.build_dir / "CTestTestfile.cmake")

    def cache_value(self, name: str) -> str:
        """A value from the build's CMakeCache.txt."""
        for line in (self.build_dir / "CMakeCache.txt").read_text().splitlines():
            key, _, value = line.partition("=")
            if key.split(":")[0] == name:
                return value
        raise AssertionError(f"{name} is not in {self.build_dir / 'CMakeCache.txt'}")
