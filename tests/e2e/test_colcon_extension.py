"""Installed means on: plain ``colcon build`` and ``colcon test`` isolate, with no flag.

The project is installed in the suite's venv, so its colcon extensions are active for that
venv's colcon (the suite turns them off for every other colcon it starts: conftest). One
workspace, built once: two unmodified ament_cmake packages of three token talkers each
and an ament_python one (examples/zero_edit). ``colcon test --parallel-workers 2
--ctest-args -j3`` with no flag: all seven pass, each on an ID of its own, and the last
line names the page it wrote, which Chromium opens with every test. The same with
colcon's own domain-ID coordinator loaded too. Control: the same packages built and
tested with ``ROS_ISOLATED_TEST_COLCON=off`` (another build base) hear each other. A
second build configures nothing again.

A venv of its own (a copy of the suite's, the project installed there from a real wheel)
then configures a one-test package with its own ``CMAKE_PROJECT_INCLUDE``: both files
run. After ``pip uninstall`` there, colcon build and test still exit 0 and configuring
says the tests are not isolated; the suite's venv, where the project is installed too,
then isolates the same build again without cleaning it.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import pytest
from helpers import capabilities, chromium
from helpers.cmake_package import build_wheel
from helpers.commands import run_cli
from helpers.domains import free_ids
from helpers.report_page import page_totals, parsed, timeline_bars, timeline_rows
from helpers.workspace import crosstalk_workspace, two_talker_packages
from lxml import etree

pytestmark = [pytest.mark.colcon, capabilities.COLCON.mark]

SECOND = ("second_talkers", ("oak", "pine", "rowan"))
CMAKE_PACKAGES = ("second_talkers", "zero_edit_talkers")
IN_PARALLEL = ["test", "--parallel-workers", "2", "--ctest-args", "-j3"]
ISOLATED = re.compile(
    r"^-- ros_isolated_test: tests of (\S+) are isolated.*\(ros-isolated-test's colcon "
    r"extension; ROS_ISOLATED_TEST_COLCON=off turns it off\): 3 tests$",
    re.M,
)
SUMMARY = re.compile(
    r"^ros-isolated-test: (\d+) tests run, (\d+) failed, (\d+) flaky, on (\d+) domain IDs; "
    r"page: (.+)$",
    re.M,
)
#: The suite's venv, where the project is installed (editable).
VENV = Path(sys.prefix)
#: The page the Chromium test draws, kept as a CI artifact.
ARTIFACT = chromium.ARTIFACTS / "colcon_extension" / "page.png"
NOT_ISOLATED = "are NOT isolated: ros-isolated-test is no longer installed"


def _colcon_env(env: Mapping[str, str], root: Path, python: Path = VENV) -> dict[str, str]:
    ws = crosstalk_workspace()
    made: dict[str, str] = ws.colcon_env(
        ws.Toolchain(python=str(python / "bin" / "python"), prefix=str(python), base_env=env)
    )
    made["COLCON_HOME"] = str(root / "colcon-home")
    made.pop("COLCON_DEFAULTS_FILE", None)
    made.pop("ROS_ISOLATED_TEST_COLCON", None)  # the suite's default (off): the extension on
    made.pop("PYTHONPATH", None)
    return made


def colcon(
    root: Path, args: Sequence[str], env: Mapping[str, str], venv: Path = VENV
) -> subprocess.CompletedProcess[str]:
    """colcon of ``venv`` run in ``root`` (its script run by that venv's Python)."""
    return subprocess.run(
        [str(venv / "bin" / "python"), str(venv / "bin" / "colcon"), *args],
        cwd=root, env=dict(env), capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip


def _workspace(root: Path) -> None:
    two_talker_packages(root, *SECOND)


def _domain_ids(root: Path, build_base: str = "build") -> dict[str, str]:
    """Each result file's test (or pytest case) and the domain ID it recorded ("" if none)."""
    found: dict[str, str] = {}
    for path in sorted((root / build_base).glob("*/test_results/*/*.xml")) + sorted(
        (root / build_base).glob("*/pytest.xml")
    ):
        tree = etree.parse(str(path))
        ids = [prop.get("value", "") for prop in tree.iter("property")
               if prop.get("name") == "ros_domain_id"]  # fmt: skip
        failed = bool(tree.xpath("//failure|//error"))
        name = path.stem if path.name != "pytest.xml" else "pytest"
        found[name] = "failed" if failed else (ids[0] if ids else "")
    return found


@pytest.fixture(scope="module")
def pool_env(module_env: dict[str, str]) -> dict[str, str]:
    return {**module_env, "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(10)))}


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory, pool_env: dict[str, str]) -> Path:
    root = tmp_path_factory.mktemp("extension")
    _workspace(root)
    return root


@pytest.fixture(scope="module")
def built(workspace: Path, pool_env: dict[str, str]) -> str:
    done = colcon(workspace, ["build", "--event-handlers", "console_cohesion+"],
                  _colcon_env(pool_env, workspace))  # fmt: skip
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-4000:]
    return done.stdout


def test_configuring_says_each_package_is_isolated_and_how_to_turn_it_off(built: str) -> None:
    assert sorted(ISOLATED.findall(built)) == list(CMAKE_PACKAGES), built[-4000:]


def test_a_second_build_configures_nothing(
    workspace: Path, built: str, pool_env: dict[str, str]
) -> None:
    caches = {name: (workspace / "build" / name / "CMakeCache.txt").stat().st_mtime_ns
              for name in CMAKE_PACKAGES}  # fmt: skip
    again = colcon(workspace, ["build", "--event-handlers", "console_cohesion+"],
                   _colcon_env(pool_env, workspace))  # fmt: skip
    assert again.returncode == 0, again.stdout[-3000:]
    assert "Configuring done" not in again.stdout
    assert "ros_isolated_test" not in again.stdout + again.stderr  # build prints nothing more
    after = {name: (workspace / "build" / name / "CMakeCache.txt").stat().st_mtime_ns
             for name in CMAKE_PACKAGES}  # fmt: skip
    assert after == caches


def _tested(workspace: Path, env: Mapping[str, str]) -> tuple[str, dict[str, str]]:
    for stale in (workspace / "build").glob("*/test_results/*/*.xml"):
        stale.unlink()
    done = colcon(workspace, IN_PARALLEL, env)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-4000:]
    return done.stdout, _domain_ids(workspace)


def _each_on_its_own(ids: dict[str, str], output: str) -> None:
    assert len(ids) == 7, (ids, output[-3000:])  # six talkers, and pytest's one file
    assert all(value.isdigit() for value in ids.values()), (ids, output[-3000:])
    assert len(set(ids.values())) == 7, ids


@pytest.mark.usefixtures("built")
def test_plain_colcon_test_isolates_every_test_and_names_its_page(
    workspace: Path, pool_env: dict[str, str]
) -> None:
    output, ids = _tested(workspace, _colcon_env(pool_env, workspace))
    _each_on_its_own(ids, output)
    (line,) = SUMMARY.findall(output)
    assert line[:4] == ("7", "0", "0", "7"), output[-2000:]
    assert output.rstrip().splitlines()[-1].startswith("ros-isolated-test: 7 tests run")
    page = workspace / line[4]
    assert page.is_file() and page.parent.name.startswith("test_")
    assert (workspace / "log" / "latest_test" / page.name).samefile(page)
    # Recorded by default into the workspace's test history, this run once.
    db = workspace / "ros_isolated_test_history.sqlite3"
    shown = run_cli(["history", "--db", str(db), "--json"], pool_env)
    assert shown.returncode == 0, shown.stderr
    recorded = {item["test"]: item["runs"] for item in json.loads(shown.stdout)}
    for token in ("ivy", "juniper", "kale", *SECOND[1]):
        assert any(f"talker_{token}" in name for name in recorded), recorded
    assert len(recorded) >= 7 and set(recorded.values()) == {1}, recorded


@capabilities.CHROMIUM.mark
def test_the_page_opens_in_chromium_with_every_test(workspace: Path) -> None:
    """The page as a person sees it: the DOM after its scripts ran, and a screenshot kept."""
    page = workspace / "log" / "latest_test" / "ros_isolated_test.html"
    dom = chromium.dump_dom(page)
    assert page_totals(dom) == {"tests": 7, "passed": 7}, page_totals(dom)
    shown = etree.tostring(dom, encoding="unicode")
    for token in ("ivy", "juniper", "kale", *SECOND[1]):
        assert f"talker_{token}" in shown
    assert "zero_edit_py" in shown  # the ament_python package's pytest item
    assert len(timeline_bars(dom)) == 7  # one bar per test, each drawn on its own ID
    assert len(timeline_rows(dom)) == 7
    chromium.screenshot(page, ARTIFACT, size=(1400, 1300))
    assert ARTIFACT.read_bytes().startswith(b"\x89PNG")


@capabilities.COLCON_COORDINATOR.mark
@pytest.mark.usefixtures("built")
def test_with_colcons_coordinator_too_every_test_still_has_its_own_id(
    workspace: Path, pool_env: dict[str, str]
) -> None:
    env = {
        **_colcon_env(pool_env, workspace),
        "PYTHONPATH": str(capabilities.COLCON_COORDINATOR_DIR),
    }
    output, ids = _tested(workspace, env)
    _each_on_its_own(ids, output)
    assert SUMMARY.search(output), output[-2000:]


SHARE_SUMMARY = re.compile(
    r"^ros-isolated-test: (\d+) tests run, (\d+) failed, (\d+) flaky, on (\d+) domain IDs "
    r"\(this machine's share (\d)/2\); page: (.+)$",
    re.M,
)


def _tree_of_share(workspace: Path, tree: Path) -> Path:
    """This run's results, copied as a CI machine uploads them (its records then go)."""
    build = workspace / "build"
    for found in build.glob("*/test_results/**/*"):
        if found.is_file():
            (tree / found.relative_to(build)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(found, tree / found.relative_to(build))
    for found in [*build.glob("*/pytest.xml"), *build.glob("**/ros_isolated_test_shard-*.json")]:
        (tree / found.relative_to(build)).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(found, tree / found.relative_to(build))
    for stale in build.glob("**/ros_isolated_test_shard-*.json"):
        stale.unlink()
    return tree


@pytest.mark.usefixtures("built")
def test_with_a_share_set_the_line_and_page_are_this_machines_and_the_merge_is_unchanged(
    workspace: Path, pool_env: dict[str, str], tmp_path: Path
) -> None:
    """ROS_ISOLATED_TEST_SHARD=I/2 on two machines (one after another on the one build):
    each line and page count that share's tests alone and say the share; ``report``
    over both trees counts every test once, as the whole run did, with no problem."""
    trees, counted = [], []
    for index in (1, 2):
        env = {**_colcon_env(pool_env, workspace), "ROS_ISOLATED_TEST_SHARD": f"{index}/2"}
        output, _ids = _tested(workspace, env)
        (line,) = SHARE_SUMMARY.findall(output)
        tests, failed, flaky, domains, share, page = line
        assert (failed, flaky, share) == ("0", "0", str(index)), output[-2000:]
        assert int(tests) == int(domains) > 0, line  # each test of the share on its own ID
        tree = _tree_of_share(workspace, tmp_path / f"share-{index}")
        trees.append(tree)
        said = run_cli(["report", "--json", str(tree)], env)
        assert said.returncode == 0, said.stdout + said.stderr
        assert json.loads(said.stdout)["total"]["tests"] == int(tests)
        drawn = parsed((workspace / page).read_text(encoding="utf-8"))
        assert page_totals(drawn) == {"tests": int(tests), "passed": int(tests)}
        assert drawn.xpath("string(//*[@id='fact-shards'])").startswith(f"{index}/2")
        counted.append(int(tests))
    assert sum(counted) == 7, counted
    merged = run_cli(["report", "--json", *map(str, trees)], pool_env)
    assert merged.returncode == 0, merged.stdout + merged.stderr
    found = json.loads(merged.stdout)
    assert (found["total"]["tests"], found["total"]["failures"]) == (7, 0), found["total"]
    assert [share["shard"] for share in found["shards"]["found"]] == ["1/2", "2/2"]
    assert found["shards"]["problems"] == []


def test_control_off_builds_and_tests_as_without_us_and_they_hear_each_other(
    workspace: Path, pool_env: dict[str, str]
) -> None:
    env = {**_colcon_env(pool_env, workspace), "ROS_ISOLATED_TEST_COLCON": "off"}
    bases = ["--build-base", "build-off", "--install-base", "install-off"]
    done = colcon(workspace, ["build", *bases, "--event-handlers", "console_cohesion+"], env)
    assert done.returncode == 0, done.stdout[-3000:]
    assert "ros_isolated_test" not in done.stdout
    assert not (workspace / "build-off" / ".ros_isolated_test").exists()
    tested = colcon(workspace, [*IN_PARALLEL[:1], *bases, *IN_PARALLEL[1:]], env)
    assert "ros-isolated-test:" not in tested.stdout
    ids = _domain_ids(workspace, "build-off")
    ids.pop("pytest")  # the ament_python package: the pytest plugin's, not colcon's
    assert "failed" in ids.values(), ids  # crosstalk on the shared domain
    assert not any(value.isdigit() for value in ids.values()), ids


_LISTS = """\
cmake_minimum_required(VERSION 3.15)
project(one_test NONE)
find_package(ament_cmake REQUIRED)
if(BUILD_TESTING)
  ament_add_test(says_id COMMAND sh -c "echo id=$ROS_DOMAIN_ID"
    GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
endif()
ament_package()
"""
_MANIFEST = """\
<?xml version="1.0"?>
<package format="3">
  <name>one_test</name>
  <version>0.1.0</version>
  <description>One test, and an include of its own.</description>
  <maintainer email="maintainer@example.com">Example Maintainer</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
OWN = 'message(STATUS "own include ran for ${PROJECT_NAME}")\n'


def _isolated_result(root: Path) -> bool:
    (path,) = (root / "build" / "one_test" / "test_results" / "one_test").glob("*.xml")
    return bool(etree.parse(str(path)).xpath("//property[@name='runner_version']"))


def test_own_include_runs_too_and_an_uninstall_or_a_move_never_breaks_the_build(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """A venv of its own (the suite's copied, the project installed from a wheel):
    configured there, then uninstalled there, then built by the suite's venv again."""
    venv = tmp_path / "venv"
    subprocess.run(["cp", "-a", str(VENV), str(venv)], check=True)
    python = str(venv / "bin" / "python")
    pip = [python, "-m", "pip", "-q", "--disable-pip-version-check"]
    subprocess.run([*pip, "uninstall", "-y", "ros-isolated-test"], check=True)  # the editable
    shutil.rmtree(venv / "share" / "ros_isolated_test", ignore_errors=True)
    (venv / "share" / "ros_isolated_test").unlink(missing_ok=True)
    wheel = build_wheel(tmp_path / "wheel")
    subprocess.run([*pip, "install", "--no-deps", str(wheel)], check=True)
    root = tmp_path / "ws"
    (root / "src" / "one_test").mkdir(parents=True)
    (root / "src" / "one_test" / "CMakeLists.txt").write_text(_LISTS)
    (root / "src" / "one_test" / "package.xml").write_text(_MANIFEST)
    (root / "own.cmake").write_text(OWN)
    build = ["build", "--event-handlers", "console_cohesion+", "--cmake-args",
             f"-DCMAKE_PROJECT_INCLUDE={root / 'own.cmake'}"]  # fmt: skip
    own_env = _colcon_env(env, root, venv)

    installed = colcon(root, build, own_env, venv)
    assert installed.returncode == 0, installed.stdout[-3000:]
    assert "own include ran for one_test" in installed.stdout
    assert "tests of one_test are isolated" in installed.stdout, installed.stdout[-3000:]
    assert colcon(root, ["test"], own_env, venv).returncode == 0
    assert _isolated_result(root)

    subprocess.run([*pip, "uninstall", "-y", "ros-isolated-test"], check=True)
    gone = colcon(root, build, own_env, venv)
    assert gone.returncode == 0, gone.stdout[-3000:]
    assert gone.stdout.count(NOT_ISOLATED) == 1, gone.stdout[-3000:]
    assert "own include ran for one_test" in gone.stdout
    tested = colcon(root, ["test"], own_env, venv)
    assert tested.returncode == 0, tested.stdout[-3000:]
    assert "ros-isolated-test:" not in tested.stdout
    assert not _isolated_result(root)

    moved = colcon(root, build, _colcon_env(env, root))  # the suite's venv: installed there
    assert moved.returncode == 0, moved.stdout[-3000:]
    assert "tests of one_test are isolated" in moved.stdout, moved.stdout[-3000:]
    assert "own include ran for one_test" in moved.stdout
    assert colcon(root, ["test"], _colcon_env(env, root)).returncode == 0
    assert _isolated_result(root)
