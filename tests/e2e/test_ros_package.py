"""End to end: this repository as a ROS package in a colcon workspace, on Ubuntu 24.04's Python.

The workspace is what a Jazzy user makes with ``vcs import``: this repository (the working
tree under test, copied as a clone would hold it) in ``src/``, beside a CMake package that
test-depends on it and calls ``find_package(ros_isolated_test)`` and
``ros_isolated_test_all()``. Real colcon, CMake and ctest and ROS 2 Jazzy's wheels run
from the distro venv (``.venv-distro``): setuptools, click, filelock and lxml at the versions
Ubuntu 24.04 ships, and this project not installed there, so all it has of ros-isolated-test
is what colcon built. Controls beside each check: without the markers colcon would list our
examples, without sourcing nothing is found, and without isolation the probes hear each
other.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import REPO
from helpers.domains import free_ids
from helpers.ros_package import (
    DISTRO_VENV,
    PACKAGE,
    copy_checkout,
    distro_env,
    in_workspace,
    run,
    ubuntu_versions,
)

import ros_isolated_test

pytestmark = [
    pytest.mark.ros,
    pytest.mark.colcon,
    capabilities.DISTRO_VENV.mark,
    capabilities.CTEST.mark,
]

#: The package that uses ours the way a user's does: test_depend, find_package, one line.
PROBES = "isolated_probes"
TOKENS = ("amber", "birch", "cobalt", "dahlia")
TALKER = REPO / "examples" / "crosstalk_demo" / "test" / "token_talker.py"

PROBES_XML = f"""<?xml version="1.0"?>
<package format="3">
  <name>{PROBES}</name>
  <version>0.0.1</version>
  <description>Crosstalk probes isolated by ros-isolated-test from the workspace.</description>
  <maintainer email="maintainers@ros-isolated-test.org">ros-isolated-test maintainers</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <test_depend>{PACKAGE}</test_depend>
  <test_depend>ament_cmake_test</test_depend>
  <test_depend>rclpy</test_depend>
  <test_depend>std_msgs</test_depend>
  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""


def _probe_tests(tokens: Sequence[str]) -> str:
    """CMake registering one plain crosstalk-probe test per token."""
    # A queued test waits inside its runner: TIMEOUT covers the wait for an ID too.
    return f"""  foreach(_token IN ITEMS {" ".join(tokens)})
    ament_add_test(probe_${{_token}}
      COMMAND "${{Python3_EXECUTABLE}}" "${{CMAKE_CURRENT_SOURCE_DIR}}/test/token_talker.py"
        "${{_token}}"
      TIMEOUT 120
      GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
  endforeach()
"""


PROBES_CMAKE = f"""cmake_minimum_required(VERSION 3.20)
project({PROBES} NONE)
find_package(ament_cmake REQUIRED)
if(BUILD_TESTING)
  find_package({PACKAGE} REQUIRED)
  ros_isolated_test_all()
{_probe_tests(TOKENS)}endif()
ament_package()
"""

#: A project that only looks for the CMake package, as any later package would.
FINDER_CMAKE = f"""cmake_minimum_required(VERSION 3.20)
project(finder NONE)
find_package({PACKAGE} REQUIRED)
"""


@dataclass(frozen=True)
class Workspace:
    root: Path
    #: A Jazzy shell on Ubuntu 24.04 before ``source install/setup.bash``.
    env: dict[str, str]
    build: subprocess.CompletedProcess[str]

    @property
    def install(self) -> Path:
        return self.root / "install" / PACKAGE

    def colcon(self, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
        return run([str(DISTRO_VENV.bin / "colcon"), *args], self.env, cwd=cwd or self.root)


def _write_probes(src: Path) -> None:
    package = src / PROBES
    (package / "test").mkdir(parents=True)
    (package / "package.xml").write_text(PROBES_XML)
    (package / "CMakeLists.txt").write_text(PROBES_CMAKE)
    shutil.copy2(TALKER, package / "test" / TALKER.name)


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """The workspace, built once with ``colcon build`` (the result kept for the tests)."""
    root = tmp_path_factory.mktemp("ros-workspace")
    copy_checkout(root / "src" / PACKAGE)
    _write_probes(root / "src")
    env = distro_env()
    build = run(
        [str(DISTRO_VENV.bin / "colcon"), "build", "--event-handlers", "console_direct+",
         "--cmake-args", f"-DPython3_EXECUTABLE={DISTRO_VENV.python}"],
        env, cwd=root,
    )  # fmt: skip
    return Workspace(root, env, build)


def _listed(output: str) -> list[tuple[str, str]]:
    """``colcon list`` as (name, path) pairs."""
    pairs = []
    for line in output.splitlines():
        name, tab, rest = line.partition("\t")
        if tab:
            pairs.append((name, rest.split("\t")[0]))
    return pairs


def test_the_venv_has_ubuntu_2404s_python_packages_and_not_this_project(
    workspace: Workspace,
) -> None:
    pins = ubuntu_versions()
    assert {"setuptools", "click", "filelock", "lxml"} <= set(pins)
    script = (
        "import json, importlib.metadata as m, importlib.util as u, sys\n"
        "names = sys.argv[1:]\n"
        "print(json.dumps({'versions': {n: m.version(n) for n in names},"
        " 'project': u.find_spec('ros_isolated_test') is not None}))"
    )
    done = run([str(DISTRO_VENV.python), "-c", script, *pins], workspace.env, workspace.root)
    assert done.returncode == 0, done.stdout
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert found["versions"] == pins
    assert found["project"] is False, "ros-isolated-test is pip-installed in the distro venv"
    assert shutil.which("ros-isolated-test", path=workspace.env["PATH"]) is None


def test_colcon_lists_this_repository_as_one_package(workspace: Workspace) -> None:
    done = workspace.colcon("list")
    assert done.returncode == 0, done.stdout
    listed = _listed(done.stdout)
    ours = [(name, path) for name, path in listed if path.startswith(f"src/{PACKAGE}")]
    assert ours == [(PACKAGE, f"src/{PACKAGE}")], done.stdout
    assert sorted(name for name, _ in listed) == sorted([PACKAGE, PROBES]), done.stdout


def test_without_its_markers_colcon_would_list_the_examples(
    workspace: Workspace, tmp_path: Path
) -> None:
    """The control: the copy does hold packages, hidden by package.xml and COLCON_IGNORE."""
    bare = copy_checkout(tmp_path / "src" / PACKAGE)
    for marker in ("package.xml", "setup.py"):  # each makes the root a package of its own
        (bare / marker).unlink()
    hidden = workspace.colcon("list", cwd=tmp_path)
    assert hidden.returncode == 0, hidden.stdout
    assert _listed(hidden.stdout) == [], "COLCON_IGNORE alone must hide the examples"
    for ignore in bare.rglob("COLCON_IGNORE"):
        ignore.unlink()
    manifests = bare.rglob("package.xml")  # the examples' (seven when this was written)
    inside = sorted(re.findall(r"<name>\s*(\S+?)\s*</name>", m.read_text())[0] for m in manifests)
    assert len(inside) >= 7, inside
    shown = workspace.colcon("list", cwd=tmp_path)
    assert sorted(name for name, _ in _listed(shown.stdout)) == inside, shown.stdout


def test_colcon_builds_it_first_and_installs_the_four_things(workspace: Workspace) -> None:
    output = workspace.build.stdout
    assert workspace.build.returncode == 0, output
    assert output.index(f"Finished <<< {PACKAGE}") < output.index(f"Starting >>> {PROBES}")
    installed = workspace.install
    assert (installed / "bin" / "ros-isolated-test").is_file()
    assert (installed / "share" / PACKAGE / "cmake" / f"{PACKAGE}Config.cmake").is_file()
    assert (installed / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    manifest = installed / "share" / PACKAGE / "package.xml"
    assert manifest.read_bytes() == (REPO / "package.xml").read_bytes()
    entry_points = list(installed.glob("lib/python3*/site-packages/*.egg-info/entry_points.txt"))
    assert len(entry_points) == 1, entry_points
    plugin_entry = "ros_isolated_test = ros_isolated_test.pytest_plugin.plugin"
    assert plugin_entry in entry_points[0].read_text()
    cache = (workspace.root / "build" / PROBES / "CMakeCache.txt").read_text()
    assert f"{PACKAGE}_DIR:PATH={installed / 'share' / PACKAGE / 'cmake'}" in cache


def test_sourced_the_command_the_plugin_and_the_cmake_package_are_found(
    workspace: Workspace, tmp_path: Path
) -> None:
    assert workspace.build.returncode == 0, workspace.build.stdout
    version = ros_isolated_test.__version__  # pyproject.toml reads it from there
    command = in_workspace(
        workspace.root, ["sh", "-c", "command -v ros-isolated-test"], workspace.env
    )
    assert command.stdout.strip() == str(workspace.install / "bin" / "ros-isolated-test")
    shown = in_workspace(workspace.root, ["ros-isolated-test", "--version"], workspace.env)
    assert shown.returncode == 0 and version in shown.stdout, shown.stdout
    pytest_help = in_workspace(workspace.root, ["python", "-m", "pytest", "--help"], workspace.env)
    assert "--ros-isolation" in pytest_help.stdout, pytest_help.stdout
    trace = in_workspace(
        workspace.root,
        ["python", "-m", "pytest", "--trace-config", "--collect-only", "-q", str(tmp_path)],
        workspace.env,
        cwd=tmp_path,
    )
    plugin = str(workspace.install / "lib")
    assert re.search(
        rf"ros_isolated_test\.pytest_plugin\.plugin' from '{re.escape(plugin)}", trace.stdout
    ), trace.stdout
    (tmp_path / "finder").mkdir()
    (tmp_path / "finder" / "CMakeLists.txt").write_text(FINDER_CMAKE)
    configure = ["cmake", "-S", str(tmp_path / "finder"), "-B", str(tmp_path / "found")]
    found = in_workspace(workspace.root, configure, workspace.env)
    assert found.returncode == 0, found.stdout
    assert f"Found ros_isolated_test: tests run through {workspace.install}" in found.stdout


def test_unsourced_none_of_them_is_found(workspace: Workspace, tmp_path: Path) -> None:
    """The control: what the sourced shell finds comes from the workspace alone."""
    python = str(DISTRO_VENV.python)
    pytest_help = run([python, "-m", "pytest", "--help"], workspace.env, tmp_path)
    assert pytest_help.returncode == 0, pytest_help.stdout
    assert "--ros-isolation" not in pytest_help.stdout
    (tmp_path / "finder").mkdir()
    (tmp_path / "finder" / "CMakeLists.txt").write_text(FINDER_CMAKE)
    configure = ["cmake", "-S", str(tmp_path / "finder"), "-B", str(tmp_path / "found")]
    missing = run(configure, workspace.env, tmp_path)
    assert missing.returncode != 0
    assert "ros_isolated_test" in missing.stdout, missing.stdout


@dataclass(frozen=True)
class Probe:
    token: str
    domain_id: str | None
    start: float
    end: float
    own_received: int
    foreign: dict[str, int]
    passed: bool


def _ctest(workspace: Workspace, tmp_path: Path, **extra: str) -> tuple[str, list[Probe]]:
    """``ctest -j4`` on the probes in the sourced workspace: ctest's output and the records."""
    build = workspace.root / "build" / PROBES
    for stale in (build / "test_results").glob("**/*.xml"):
        stale.unlink()
    records = tmp_path / "records"
    env = {
        **workspace.env,
        "ROS_ISOLATED_TEST_LOCK_DIR": str(tmp_path / "locks"),
        "CROSSTALK_RECORD_DIR": str(records),
        **extra,
    }
    done = in_workspace(workspace.root, ["ctest", "-j4", "--output-on-failure"], env, cwd=build)
    log = build / "Testing" / "Temporary" / "LastTest.log"
    output = done.stdout + (log.read_text(errors="replace") if log.is_file() else "")
    probes = []
    for path in sorted(records.glob("*.json")):
        data = json.loads(path.read_text())
        probes.append(Probe(**{key: data[key] for key in Probe.__dataclass_fields__}))
    return output, probes


def test_four_probes_pass_under_ctest_j4_on_two_ids_half_of_them_waiting(
    workspace: Workspace, tmp_path: Path
) -> None:
    assert workspace.build.returncode == 0, workspace.build.stdout
    pool = [str(domain_id) for domain_id in free_ids(2)]
    output, probes = _ctest(workspace, tmp_path, ROS_ISOLATED_TEST_DOMAINS=",".join(pool))
    assert "100% tests passed" in output, output
    assert sorted(probe.token for probe in probes) == sorted(TOKENS), output
    failed = {probe.token: probe.foreign for probe in probes if not probe.passed}
    assert not failed, f"crosstalk despite isolation: {failed}"
    assert all(probe.own_received > 0 for probe in probes)
    assert sorted(probe.domain_id or "" for probe in probes) == sorted(pool * 2), probes
    for domain_id in pool:  # two tests per ID, one after the other: the second one waited
        first, second = sorted(
            (p for p in probes if p.domain_id == domain_id), key=lambda p: p.start
        )
        assert first.end < second.start, (first, second)
    assert output.count("waiting for a free ROS_DOMAIN_ID") >= 2, output
    assert "Traceback" not in output, output


def test_without_isolation_the_same_probes_hear_each_other(
    workspace: Workspace, tmp_path: Path
) -> None:
    """The control: the probes fail when they share a domain, so the passes mean isolation."""
    assert workspace.build.returncode == 0, workspace.build.stdout
    output, probes = _ctest(workspace, tmp_path, DISABLE_ROS_ISOLATION="1")
    assert len(probes) == len(TOKENS), output
    heard = [probe for probe in probes if not probe.passed and probe.foreign]
    assert len(heard) >= 2, probes


#: A third-party package: plain ament_add_test, no word of ros-isolated-test anywhere.
ZERO_EDIT = "third_party_probes"
ZERO_EDIT_XML = PROBES_XML.replace(PROBES, ZERO_EDIT).replace(
    f"  <test_depend>{PACKAGE}</test_depend>\n", ""
)
ZERO_EDIT_CMAKE = f"""cmake_minimum_required(VERSION 3.20)
project({ZERO_EDIT} NONE)
find_package(ament_cmake REQUIRED)
if(BUILD_TESTING)
  find_package(ament_cmake_test REQUIRED)
{_probe_tests(TOKENS[:2])}endif()
ament_package()
"""


def test_the_zero_edit_recipe_works_from_the_workspace(tmp_path: Path) -> None:
    """Build this package first, then the rest with the flag: a package that never names us
    runs its tests through the runner the workspace built, each on an ID of its own."""
    root = tmp_path / "ws"
    copy_checkout(root / "src" / PACKAGE)
    package = root / "src" / ZERO_EDIT
    (package / "test").mkdir(parents=True)
    (package / "package.xml").write_text(ZERO_EDIT_XML)
    (package / "CMakeLists.txt").write_text(ZERO_EDIT_CMAKE)
    shutil.copy2(TALKER, package / "test" / TALKER.name)
    env = distro_env()
    colcon = str(DISTRO_VENV.bin / "colcon")
    first = run([colcon, "build", "--packages-select", PACKAGE], env, root)
    assert first.returncode == 0, first.stdout
    rest = (
        f"{colcon} build --event-handlers console_direct+ --cmake-args"
        ' -DCMAKE_PROJECT_INCLUDE="$(ros-isolated-test cmake-include)"'
        f" -DPython3_EXECUTABLE={DISTRO_VENV.python}"
    )
    second = in_workspace(root, ["bash", "-c", rest], env)
    assert second.returncode == 0, second.stdout
    assert f"ros_isolated_test: tests of {ZERO_EDIT} are isolated" in second.stdout, second.stdout
    runner = root / "install" / PACKAGE / "lib"
    registered = (root / "build" / ZERO_EDIT / "CTestTestfile.cmake").read_text()
    assert registered.count(f'"-u" "{runner}') == 2, registered
    pool = [str(domain_id) for domain_id in free_ids(2)]
    records = tmp_path / "records"
    test_env = {
        **env,
        "ROS_ISOLATED_TEST_DOMAINS": ",".join(pool),
        "ROS_ISOLATED_TEST_LOCK_DIR": str(tmp_path / "locks"),
        "CROSSTALK_RECORD_DIR": str(records),
    }
    build = root / "build" / ZERO_EDIT
    tested = in_workspace(root, ["ctest", "-j2", "--output-on-failure"], test_env, cwd=build)
    assert "100% tests passed" in tested.stdout, tested.stdout
    ids = sorted(json.loads(path.read_text())["domain_id"] for path in records.glob("*.json"))
    assert ids == sorted(pool), ids


def test_colcon_test_of_the_package_checks_the_install(workspace: Workspace) -> None:
    """``colcon test`` in a user's workspace runs the install check, never our suite."""
    assert workspace.build.returncode == 0, workspace.build.stdout
    done = workspace.colcon(
        "test", "--packages-select", PACKAGE, "--event-handlers", "console_direct+"
    )
    assert done.returncode == 0, done.stdout
    ran = re.search(r"^Ran (\d+) tests? in", done.stdout, re.MULTILINE)
    assert ran is not None and int(ran[1]) >= 3, done.stdout
    assert "OK" in done.stdout[ran.end() :], done.stdout
