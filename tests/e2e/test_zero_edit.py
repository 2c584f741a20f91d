"""Zero edits: a whole colcon workspace isolated without touching its packages.

``ros-isolated-test cmake-include`` prints a CMake file given to every package as
``CMAKE_PROJECT_INCLUDE``. examples/zero_edit holds two ament_cmake packages (plain
ament_add_test token tests; a gtest beside two more) and an ament_python one, none of
which mentions ros-isolated-test. Built with the README's recipe and tested with packages
and tests in parallel, every test passes on a domain ID of its own, tests of different
packages at once; built and tested without it, they hear each other, across packages too
(the control). Configure-only projects check each edge of the include (a RUNNER of its own,
a package already calling ros_isolated_test_all(), a plain CMake project, subprojects, the
opt-out, no runner); tiny workspaces check each documented colcon route with real colcon;
a real wheel prints its own installed file.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from helpers import capabilities
from helpers.cmake_package import build_wheel, install_wheel, runners_of
from helpers.commands import REPO, run_cli
from helpers.distros import JAZZY, KILTED, Tools
from helpers.domains import free_ids
from helpers.results import load_result
from helpers.workspace import crosstalk_workspace

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Record, ResultSummary

pytestmark = [pytest.mark.colcon, capabilities.COLCON.mark]

ZERO_EDIT = REPO / "examples" / "zero_edit"
TOKEN_TALKER = REPO / "examples" / "crosstalk_demo" / "test" / "token_talker.py"
#: Every test of the workspace, by the token it records, and its package.
PACKAGE_OF = {
    "ivy": "zero_edit_talkers",
    "juniper": "zero_edit_talkers",
    "kale": "zero_edit_talkers",
    "lilac": "zero_edit_gtest",
    "mint": "zero_edit_gtest",
    "gtest": "zero_edit_gtest",
    "nettle": "zero_edit_py",
}
TOKEN_TESTS = sorted(token for token in PACKAGE_OF if token != "gtest")
CMAKE_PACKAGES = ("zero_edit_gtest", "zero_edit_talkers")
#: The README's recipe, word for word, and how the workspace is tested.
RECIPE = "colcon build --cmake-args -DCMAKE_PROJECT_INCLUDE=$(ros-isolated-test cmake-include)"
IN_PARALLEL = "colcon test --parallel-workers 3 --ctest-args -j3"
#: The status line of an isolated package (CMake prints it after "-- ").
ISOLATED = re.compile(r"^-- ros_isolated_test: tests of (\S+) are isolated.* run by (\S+) ", re.M)
#: The whole of that line, from its first word.
ISOLATED_LINE = re.compile(r"^-- (ros_isolated_test: tests of \S+ are isolated.*)$", re.M)
#: The line naming the tests that are not isolated, from its first word.
NOT_ISOLATED_LINE = re.compile(r"^-- (ros_isolated_test: NOT isolated, .*)$", re.M)
NOT_ISOLATED = "ros_isolated_test: tests of {} are NOT isolated (ROS_ISOLATED_TEST_ALL is OFF)"


def _colcon_env(base: Mapping[str, str]) -> dict[str, str]:
    """colcon's environment (the venv's ament_cmake and colcon first) over ``base``."""
    ws = crosstalk_workspace()
    env: dict[str, str] = ws.colcon_env(ws.Toolchain(base_env=base))
    return env


class Workspace:
    """A colcon workspace in a folder of its own, used as its README says: ``cd`` there."""

    def __init__(self, root: Path, env: Mapping[str, str]) -> None:
        self.root = root
        self.records = root / "records"
        # colcon reads no settings of the machine's user (a defaults file that isolates).
        self.env = {**_colcon_env(env), "CROSSTALK_RECORD_DIR": str(self.records)}
        self.env["COLCON_HOME"] = str(root / "colcon-home")
        self.env.pop("COLCON_DEFAULTS_FILE", None)

    def shell(self, line: str, check: bool = True) -> str:
        """``line`` run by bash in the workspace (so ``$(...)`` is the shell's); its output."""
        self.records.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(
            ["bash", "-c", line], cwd=self.root, env=self.env,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, check=False,
        )  # fmt: skip
        if check and done.returncode != 0:
            raise AssertionError(f"{line} failed:\n{done.stdout}")
        return done.stdout

    def runners(self, package: str) -> dict[str, str]:
        return runners_of(self.root / "build" / package / "CTestTestfile.cmake")

    def build_log(self, package: str, stream: str = "stdout") -> str:
        return (self.root / "log" / "latest_build" / package / f"{stream}.log").read_text()

    def records_by_token(self) -> dict[str, Record]:
        records: dict[str, Record] = crosstalk_workspace().read_records(self.records)
        return records

    def result_summary(self) -> ResultSummary:
        summary: ResultSummary = crosstalk_workspace().result_summary(self.root)
        return summary


def _zero_edit_workspace(root: Path, env: Mapping[str, str]) -> Workspace:
    """examples/zero_edit's packages in ``root/src``, the token talker beside them."""
    shutil.copytree(ZERO_EDIT, root / "src" / "zero_edit")
    talker = root / "src" / "crosstalk_demo" / "test"
    talker.mkdir(parents=True)
    shutil.copy(TOKEN_TALKER, talker)
    return Workspace(root, env)


@pytest.fixture(scope="module")
def pool_env(module_env: dict[str, str]) -> dict[str, str]:
    """The module's lock dir and a pool of IDs free now: more than the workspace's tests."""
    return {**module_env, "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(10)))}


@pytest.fixture(scope="module")
def recipe(tmp_path_factory: pytest.TempPathFactory, pool_env: dict[str, str]) -> Workspace:
    """The workspace built with the recipe and tested once, packages and tests in parallel."""
    capabilities.require(capabilities.GTEST)
    ws = _zero_edit_workspace(tmp_path_factory.mktemp("recipe"), pool_env)
    ws.shell(RECIPE)
    ws.shell(IN_PARALLEL, check=False)
    return ws


@pytest.fixture(scope="module")
def control(tmp_path_factory: pytest.TempPathFactory, pool_env: dict[str, str]) -> Workspace:
    """The same workspace, built and tested the same way without ros-isolated-test."""
    capabilities.require(capabilities.GTEST)
    ws = _zero_edit_workspace(tmp_path_factory.mktemp("control"), pool_env)
    ws.shell("colcon build")
    ws.shell(f"{IN_PARALLEL} --pytest-args -p no:ros_isolated_test", check=False)
    return ws


def test_the_workspace_never_mentions_ros_isolated_test() -> None:
    """Its packages, that is: the README beside them says what they are for."""
    files = [path for path in ZERO_EDIT.glob("*/**/*") if path.is_file()]
    assert {path.parent.parent.name for path in files if path.name == "package.xml"} == {
        "zero_edit"
    }
    for path in files:
        text = path.read_text().lower()
        assert "isolated_test" not in text and "isolated-test" not in text, path


def test_with_the_recipe_every_test_passes_on_a_distinct_id(
    recipe: Workspace, runner_script: str
) -> None:
    for package in CMAKE_PACKAGES:
        assert set(recipe.runners(package).values()) == {runner_script}, package
    records = recipe.records_by_token()
    assert sorted(records) == sorted(PACKAGE_OF), f"records: {sorted(records)}"
    failed = {r.token: r.foreign for r in records.values() if not r.passed}
    assert not failed, f"crosstalk despite the recipe: {failed}"
    ids = [r.domain_id for r in records.values()]
    assert None not in ids and len(set(ids)) == len(ids), f"domain IDs: {ids}"
    summary = recipe.result_summary()
    assert (summary.returncode, summary.errors, summary.failures) == (0, 0, 0), summary.line


def test_with_the_recipe_tests_of_different_packages_ran_at_once(recipe: Workspace) -> None:
    """Packages in parallel: two tests of different packages were alive together, each
    on an ID of its own (a machine-wide pool, not one per package)."""
    records = recipe.records_by_token()
    together = [
        (a, b)
        for a in TOKEN_TESTS
        for b in TOKEN_TESTS
        if PACKAGE_OF[a] < PACKAGE_OF[b]
        and records[a].start < records[b].end
        and records[b].start < records[a].end
    ]
    assert together, {t: (r.start, r.end) for t, r in records.items()}
    assert all(records[a].domain_id != records[b].domain_id for a, b in together)


def test_configuring_says_once_per_package_which_runner(
    recipe: Workspace, control: Workspace, runner_script: str
) -> None:
    """One line per CMake package (googletest's own project() calls add none), none for
    the ament_python package, and nothing on stderr that the control did not print."""
    for package in CMAKE_PACKAGES:
        said = ISOLATED.findall(recipe.build_log(package))
        assert said == [(package, runner_script)], recipe.build_log(package)
        assert recipe.build_log(package, "stderr") == control.build_log(package, "stderr")
        assert not ISOLATED.findall(control.build_log(package)), control.build_log(package)
    assert "ros_isolated_test" not in recipe.build_log("zero_edit_py")


def test_without_the_recipe_the_workspace_hears_crosstalk(control: Workspace) -> None:
    for package in CMAKE_PACKAGES:
        runners = control.runners(package).values()
        assert all(r.endswith("/ament_cmake_test/cmake/run_test.py") for r in runners)
    records = control.records_by_token()
    assert sorted(records) == sorted(PACKAGE_OF), f"records: {sorted(records)}"
    assert all(r.domain_id is None for r in records.values())
    heard = {t: records[t].foreign for t in TOKEN_TESTS if records[t].foreign}
    assert len(heard) >= 4, f"only {len(heard)} of 6 heard crosstalk: control too weak"
    across = {
        t: [other for other in foreign if PACKAGE_OF.get(other, PACKAGE_OF[t]) != PACKAGE_OF[t]]
        for t, foreign in heard.items()
    }
    assert any(across.values()), f"no test heard another package's: {heard}"
    assert control.result_summary().failures > 0


# Each edge of the include, configured with cmake alone (no build, no test run).

_MANIFEST = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name><version>0.1.0</version><description>A test package.</description>
  <maintainer email="maintainer@example.com">Example Maintainer</maintainer>
  <license>Apache-2.0</license>
  <export><build_type>{build_type}</build_type></export>
</package>
"""


def _package(
    folder: Path,
    body: str,
    build_type: str | None = "ament_cmake",
    name: str = "tiny",
    minimum: str = "3.15",
) -> Path:
    """A project folder: a CMakeLists.txt that starts with ``project(name NONE)``, and a
    package.xml of ``build_type`` (none for None)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "CMakeLists.txt").write_text(
        f"cmake_minimum_required(VERSION {minimum})\nproject({name} NONE)\n{body}"
    )
    if build_type is not None:
        (folder / "package.xml").write_text(_MANIFEST.format(name=name, build_type=build_type))
    return folder


@pytest.fixture(scope="module")
def include_file(module_env: dict[str, str]) -> str:
    done = run_cli(["cmake-include"], module_env)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def _configure(
    source: Path, build: Path, env: Mapping[str, str], *args: str
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["cmake", "-S", str(source), "-B", str(build), f"-DPython3_EXECUTABLE={sys.executable}",
         *args],
        env=_colcon_env(env), capture_output=True, text=True, check=False,
    )  # fmt: skip


def _configured(
    source: Path, build: Path, env: Mapping[str, str], *args: str
) -> subprocess.CompletedProcess[str]:
    done = _configure(source, build, env, *args)
    assert done.returncode == 0, done.stdout + done.stderr
    return done


def _ctest_file(build: Path) -> str:
    """The CTestTestfile.cmake CMake wrote, the build folder's path made neutral and the
    backtraces (which file defined which function) left out."""
    text = (build / "CTestTestfile.cmake").read_text().replace(str(build), "<build>")
    return re.sub(r' _BACKTRACE_TRIPLES "[^"]*"', "", text)


def _cache(build: Path) -> list[str]:
    """CMakeCache.txt's entries, the build folder's path made neutral."""
    lines = (build / "CMakeCache.txt").read_text().replace(str(build), "<build>").splitlines()
    return [line for line in lines if line and not line.startswith(("#", "//"))]


def test_cmake_include_prints_an_installed_file_and_a_colcon_defaults_file(
    module_env: dict[str, str], include_file: str
) -> None:
    path = Path(include_file)
    assert path.is_absolute() and path.is_file(), include_file
    assert path.name == "ros_isolated_test_project_include.cmake"
    assert (path.parent / "ros_isolated_testConfig.cmake").is_file()
    done = run_cli(["cmake-include", "--colcon-defaults"], module_env)
    assert done.returncode == 0, done.stderr
    # What colcon makes of it: test_a_colcon_defaults_file_isolates_every_build.
    lines = [line for line in done.stdout.splitlines() if not line.startswith("#")]
    argument = json.dumps(f"-DCMAKE_PROJECT_INCLUDE={include_file}")
    assert lines == ["build:", "  cmake-args:", f"    - {argument}"], done.stdout


def test_a_test_with_a_runner_of_its_own_keeps_it(
    tmp_path: Path, env: dict[str, str], include_file: str, runner_script: str
) -> None:
    source = _package(
        tmp_path / "src",
        "find_package(ament_cmake REQUIRED)\n"
        "ament_add_test(plain COMMAND true)\n"
        'ament_add_test(own COMMAND true RUNNER "${ament_cmake_test_DIR}/run_test.py")\n',
    )
    _configured(source, tmp_path / "build", env, f"-DCMAKE_PROJECT_INCLUDE={include_file}")
    runners = runners_of(tmp_path / "build" / "CTestTestfile.cmake")
    assert runners["plain"] == runner_script, runners
    assert runners["own"].endswith("/ament_cmake_test/cmake/run_test.py"), runners


#: Tests registered with upstream's isolated runner (ament_cmake_ros's run_test_isolated.py),
#: each naming it its own way, and tests around them that keep their RUNNER.
_UPSTREAM_BODY = """find_package(ament_cmake REQUIRED)
find_package(ament_cmake_ros REQUIRED)
set(upstream "${ament_cmake_ros_DIR}/run_test_isolated.py")
ament_add_test(by_path COMMAND true RUNNER "${upstream}" GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
ament_add_test(spelled COMMAND true RUNNER "${ament_cmake_ros_DIR}/../cmake//run_test_isolated.py")
ament_add_test(linked COMMAND true RUNNER "{linked}")
ament_add_ros_isolated_pytest_test(by_macro test_nothing.py)
ament_add_test(pinned COMMAND true RUNNER "${upstream}" ENV ROS_DOMAIN_ID=5)
ament_add_test(copied COMMAND true RUNNER "${CMAKE_CURRENT_SOURCE_DIR}/cmake/run_test_isolated.py")
ament_add_test(own COMMAND true RUNNER "${ament_cmake_test_DIR}/run_test.py")
ament_add_test(plain COMMAND true)
add_subdirectory(raw)
"""
#: A plain add_test and a file of tests ctest reads when it runs (gtest_discover_tests).
_RAW_BODY = """add_test(NAME raw COMMAND true)
file(WRITE "${CMAKE_CURRENT_BINARY_DIR}/discovered.cmake" "")
set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES
  "${CMAKE_CURRENT_BINARY_DIR}/discovered.cmake")
"""


@capabilities.CTEST.mark
def test_upstreams_isolated_runner_is_taken_over_and_every_test_left_out_is_named(
    tmp_path: Path, env: dict[str, str], include_file: str, runner_script: str
) -> None:
    """Upstream's run_test_isolated.py, however its path is spelled (a link to it, its own
    macro), runs through ours; with ROS_DOMAIN_ID in its ENV it is kept (ours would
    refuse it), and so is any other RUNNER, even a copy of upstream's file in the package.
    The line counts the tests taken over, the next names each test not isolated and why.
    The control: a package whose every test goes through ament_add_test says no more."""
    upstream = JAZZY.upstream_runner
    (tmp_path / "links").mkdir()
    (tmp_path / "links" / "run_test_isolated.py").symlink_to(upstream)
    body = _UPSTREAM_BODY.replace("{linked}", str(tmp_path / "links" / "run_test_isolated.py"))
    source = _package(tmp_path / "src", body)
    _package(source / "raw", _RAW_BODY, build_type=None, name="raw")
    (source / "test_nothing.py").write_text("")
    (source / "cmake").mkdir()
    shutil.copy(upstream, source / "cmake" / "run_test_isolated.py")
    done = _configured(source, tmp_path / "build", env, f"-DCMAKE_PROJECT_INCLUDE={include_file}")

    runners = runners_of(tmp_path / "build" / "CTestTestfile.cmake")
    taken = ("by_path", "spelled", "linked", "by_macro")
    assert {name: runners[name] for name in (*taken, "plain")} == dict.fromkeys(
        (*taken, "plain"), runner_script
    ), runners
    assert runners["pinned"] == str(upstream), runners
    assert runners["copied"] == str(source / "cmake" / "run_test_isolated.py"), runners
    assert runners["own"].endswith("/ament_cmake_test/cmake/run_test.py"), runners
    (line,) = ISOLATED_LINE.findall(done.stdout)
    assert line.endswith(": 5 tests, 4 of them taken over from upstream's run_test_isolated.py")
    (left_out,) = NOT_ISOLATED_LINE.findall(done.stdout)
    assert left_out.startswith("ros_isolated_test: NOT isolated, 4 tests of tiny: "), left_out
    for named in (
        "copied (its own RUNNER run_test_isolated.py)",
        "own (its own RUNNER run_test.py)",
        "pinned (upstream's run_test_isolated.py, kept: its ENV sets ROS_DOMAIN_ID)",
        "raw (a plain add_test(), not ament_add_test(): no RUNNER to replace)",
    ):
        assert named in left_out, left_out
    assert re.search(
        r"that ctest discovers when it runs \(TEST_INCLUDE_FILES, e\.g\. gtest_discover_tests, "
        rf"in {re.escape(str(source / 'raw'))}\) are NOT isolated",
        done.stdout,
    ), done.stdout

    # Taken over, it runs through ours: our result file, on an ID of ours.
    ctest = subprocess.run(
        ["ctest", "-R", "^by_path$", "--output-on-failure"], cwd=tmp_path / "build",
        env=_colcon_env(env), capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert ctest.returncode == 0, ctest.stdout + ctest.stderr
    result = load_result(tmp_path / "build" / "test_results" / "tiny" / "by_path.xml")
    assert result.properties.get("ros_domain_id"), result.properties

    control = _package(tmp_path / "control", "find_package(ament_cmake REQUIRED)\n"
                       "ament_add_test(plain COMMAND true)\n")  # fmt: skip
    said = _configured(control, tmp_path / "control-build", env,
                       f"-DCMAKE_PROJECT_INCLUDE={include_file}").stdout  # fmt: skip
    assert [line.rsplit(": ", 1)[1] for line in ISOLATED_LINE.findall(said)] == ["1 test"], said
    assert not NOT_ISOLATED_LINE.findall(said) and "NOT" not in said, said


@capabilities.KILTED.mark
@capabilities.CTEST.mark
def test_kilteds_isolated_runner_is_taken_over_too(tmp_path: Path, env: dict[str, str]) -> None:
    """Kilted's run_test_isolated.py (rmw_test_fixture), as its ament_add_ros_isolated_test
    names it: configured with Kilted's CMake packages, the test runs through ours."""
    kilted = Tools.on(KILTED)
    kilted_env = kilted.env(env)
    include = kilted.run_cli(["cmake-include"], kilted_env).stdout.strip()
    source = _package(
        tmp_path / "src",
        "find_package(ament_cmake REQUIRED)\nfind_package(ament_cmake_ros REQUIRED)\n"
        "ament_add_ros_isolated_test(k COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n",
    )
    build = tmp_path / "build"
    done = subprocess.run(
        ["cmake", "-S", str(source), "-B", str(build), f"-DPython3_EXECUTABLE={kilted.python}",
         f"-DCMAKE_PROJECT_INCLUDE={include}"],
        env=kilted_env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert runners_of(build / "CTestTestfile.cmake") == {"k": kilted.runner_script()}
    (line,) = ISOLATED_LINE.findall(done.stdout)
    assert line.endswith(": 1 test, 1 of them taken over from upstream's run_test_isolated.py")
    ctest = subprocess.run(["ctest", "--output-on-failure"], cwd=build, env=kilted_env,
                           capture_output=True, text=True, check=False)  # fmt: skip
    assert ctest.returncode == 0, ctest.stdout + ctest.stderr
    result = load_result(build / "test_results" / "tiny" / "k.xml")
    assert result.properties.get("ros_domain_id"), result.properties


_EXPORT = "<export><build_type{condition}>{build_type}</build_type></export>"


@pytest.mark.parametrize(
    ("extra", "export", "ros_version", "isolated"),
    [
        ("", _EXPORT.format(condition="", build_type="ament_cmake"), None, True),
        (f"<!-- {_EXPORT.format(condition='', build_type='ament_cmake')} -->",
         _EXPORT.format(condition="", build_type="cmake"), None, False),
        (f"<description><![CDATA[{_EXPORT.format(condition='', build_type='ament_cmake')}]]>"
         "</description>", _EXPORT.format(condition="", build_type="cmake"), None, False),
        ("", _EXPORT.format(condition=' condition="$ROS_VERSION == 2"', build_type="ament_cmake")
         .replace("<export>", '<export><build_type condition="$ROS_VERSION == 1">catkin'
                  "</build_type>"), "2", True),
        ("", _EXPORT.format(condition=' condition="$ROS_VERSION == 1"', build_type="ament_cmake"),
         "2", False),
    ],
    ids=["control-export", "in-a-comment", "in-cdata", "condition-holds", "condition-fails"],
)  # fmt: skip
def test_the_manifest_is_read_as_markup_not_searched_as_text(
    tmp_path: Path,
    env: dict[str, str],
    include_file: str,
    extra: str,
    export: str,
    ros_version: str | None,
    isolated: bool,
) -> None:
    """Only an exported <build_type>ament_cmake</build_type> whose condition holds makes an
    ament_cmake package: one in a comment or a CDATA section is text (the project is left
    untouched, nothing found), and so is one whose condition does not hold here."""
    source = _package(tmp_path / "src", "enable_testing()\nadd_test(NAME t COMMAND true)\n",
                      build_type=None)  # fmt: skip
    (source / "package.xml").write_text(
        _MANIFEST.replace("<export><build_type>{build_type}</build_type></export>", extra + export)
        .format(name="tiny")
    )  # fmt: skip
    configure_env = {**env, "ROS_VERSION": ros_version} if ros_version else env
    done = _configured(source, tmp_path / "build", configure_env,
                       f"-DCMAKE_PROJECT_INCLUDE={include_file}")  # fmt: skip
    found = any(e.startswith("ament_cmake_test_DIR:") for e in _cache(tmp_path / "build"))
    assert (bool(ISOLATED_LINE.findall(done.stdout)), found) == (isolated, isolated), done.stdout
    if not isolated:
        assert "ros_isolated_test" not in done.stdout + done.stderr, done.stdout


def test_a_package_calling_ros_isolated_test_all_itself_is_unchanged(
    tmp_path: Path, env: dict[str, str], include_file: str, runner_script: str
) -> None:
    """Configured with and without the include, the same tests with the same arguments:
    no second wrapper, the package's RERUNS and its macros' RESOURCES kept; one line
    either way, naming who isolated them."""
    source = _package(
        tmp_path / "src",
        "find_package(ament_cmake REQUIRED)\nfind_package(ros_isolated_test 0.1 REQUIRED)\n"
        "ros_isolated_test_all(RERUNS 2)\n"
        "ament_add_test(wrapped COMMAND true)\n"
        "ros_isolated_add_test(macro COMMAND true RESOURCES cpu=1)\n"
        'ament_add_test(own COMMAND true RUNNER "${ament_cmake_test_DIR}/run_test.py")\n',
        minimum="3.20",
    )
    included = _configured(
        source, tmp_path / "with", env, f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    )
    alone = _configured(source, tmp_path / "without", env)
    for done, how in ((included, "(CMAKE_PROJECT_INCLUDE; "), (alone, "(ros_isolated_test_all())")):
        assert ISOLATED.findall(done.stdout) == [("tiny", runner_script)], done.stdout
        assert f"{how}" in done.stdout and ": 2 tests\n" in done.stdout, done.stdout
    assert _ctest_file(tmp_path / "with") == _ctest_file(tmp_path / "without")
    ctest_file = _ctest_file(tmp_path / "with")
    assert ctest_file.count(f'"-u" "{runner_script}"') == 2, ctest_file
    assert '"ROS_ISOLATED_TEST_RERUNS=2"' in ctest_file, ctest_file


@pytest.mark.parametrize("build_type", [None, "cmake"], ids=["no-package-xml", "cmake-package"])
def test_a_plain_cmake_project_is_left_untouched(
    tmp_path: Path, env: dict[str, str], include_file: str, build_type: str | None
) -> None:
    """Same output, same tests, same cache but the include's own entry, where ament_cmake
    could be found (the control: the same project as an ament_cmake package is isolated).
    An old cmake_minimum_required too: the include brings its own policies."""
    body = "enable_testing()\nadd_test(NAME plain COMMAND true)\n"
    source = _package(tmp_path / "src", body, build_type, minimum="2.8.12")
    included = _configured(
        source, tmp_path / "with", env, f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    )
    alone = _configured(source, tmp_path / "without", env)
    assert included.stdout.replace(str(tmp_path / "with"), "<build>") == alone.stdout.replace(
        str(tmp_path / "without"), "<build>"
    )
    assert included.stderr.replace(str(tmp_path / "with"), "<build>") == alone.stderr.replace(
        str(tmp_path / "without"), "<build>"
    )
    assert _ctest_file(tmp_path / "with") == _ctest_file(tmp_path / "without")
    extra = set(_cache(tmp_path / "with")) ^ set(_cache(tmp_path / "without"))
    assert extra == {f"CMAKE_PROJECT_INCLUDE:UNINITIALIZED={include_file}"}, extra

    ament = _package(tmp_path / "ament", body, "ament_cmake")
    control = _configured(
        ament, tmp_path / "ament-build", env, f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    )
    assert ISOLATED.findall(control.stdout), control.stdout
    assert any(e.startswith("ament_cmake_test_DIR:") for e in _cache(tmp_path / "ament-build"))


def test_every_project_call_a_subproject_too(
    tmp_path: Path, env: dict[str, str], include_file: str, runner_script: str
) -> None:
    """A project() in a subdirectory that finds ament_cmake_test again keeps the wrapper,
    a second project() of the package says nothing more; an ament package below a plain
    top-level project is isolated by its own project() call."""
    outer = _package(
        tmp_path / "outer",
        "add_subdirectory(vendored)\nfind_package(ament_cmake REQUIRED)\n"
        "project(outer VERSION 0.2 LANGUAGES NONE)\n"
        "ament_add_test(outer_test COMMAND true)\n",
        name="outer",
    )
    _package(
        outer / "vendored",
        "find_package(ament_cmake_test REQUIRED)\nament_add_test(vendored_test COMMAND true)\n",
        build_type=None,
        name="vendored",
    )
    done = _configured(
        outer, tmp_path / "outer-build", env, f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    )
    assert ISOLATED.findall(done.stdout) == [("outer", runner_script)], done.stdout
    found = {
        **runners_of(tmp_path / "outer-build" / "CTestTestfile.cmake"),
        **runners_of(tmp_path / "outer-build" / "vendored" / "CTestTestfile.cmake"),
    }
    assert found == {"outer_test": runner_script, "vendored_test": runner_script}, found

    top = _package(
        tmp_path / "top",
        "enable_testing()\nadd_subdirectory(pkg)\nadd_test(NAME top_test COMMAND true)\n",
        build_type=None,
        name="top",
    )
    _package(
        top / "pkg",
        "find_package(ament_cmake REQUIRED)\nament_add_test(pkg_test COMMAND true)\n",
        name="pkg",
    )
    done = _configured(top, tmp_path / "top-build", env, f"-DCMAKE_PROJECT_INCLUDE={include_file}")
    assert ISOLATED.findall(done.stdout) == [("pkg", runner_script)], done.stdout
    pkg_runners = runners_of(tmp_path / "top-build" / "pkg" / "CTestTestfile.cmake")
    assert pkg_runners == {"pkg_test": runner_script}, pkg_runners
    assert 'add_test(top_test "true")' in _ctest_file(tmp_path / "top-build")


def test_ros_isolated_test_all_off_opts_out(
    tmp_path: Path, env: dict[str, str], include_file: str, runner_script: str
) -> None:
    """OFF: ament's runner, one line saying so, nothing of ours found, kept by the cache
    until ON; the package's own ros_isolated_test_all() still applies. Without OFF (the
    control): ours."""
    body = "find_package(ament_cmake REQUIRED)\nament_add_test(t COMMAND true)\n"
    source = _package(tmp_path / "src", body)
    include = f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    build = tmp_path / "build"
    for args in (("-DROS_ISOLATED_TEST_ALL=OFF",), ()):  # the second from the cache
        off = _configured(source, build, env, include, *args)
        assert off.stdout.count("ros_isolated_test:") == 1, off.stdout
        assert NOT_ISOLATED.format("tiny") in off.stdout, off.stdout
        assert runners_of(build / "CTestTestfile.cmake")["t"].endswith("/run_test.py")
        assert not any(e.startswith("ros_isolated_test_DIR:") for e in _cache(build))
    _configured(source, build, env, "-DROS_ISOLATED_TEST_ALL=ON")
    assert runners_of(build / "CTestTestfile.cmake") == {"t": runner_script}
    _configured(source, tmp_path / "never-off", env, include)
    assert runners_of(tmp_path / "never-off" / "CTestTestfile.cmake") == {"t": runner_script}

    own = _package(
        tmp_path / "own",
        "find_package(ament_cmake REQUIRED)\nfind_package(ros_isolated_test REQUIRED)\n"
        "ros_isolated_test_all()\nament_add_test(t COMMAND true)\n",
    )
    _configured(own, tmp_path / "own-off", env, include, "-DROS_ISOLATED_TEST_ALL=OFF")
    assert runners_of(tmp_path / "own-off" / "CTestTestfile.cmake") == {"t": runner_script}


def test_a_package_wrapping_ament_add_test_itself_is_told_to_opt_out(
    tmp_path: Path, env: dict[str, str], include_file: str
) -> None:
    """CMake keeps one earlier definition: a package's own wrapper after ours would recurse.
    The error names the opt-out, and the opt-out works: the package's wrapper alone."""
    source = _package(
        tmp_path / "src",
        "find_package(ament_cmake REQUIRED)\n"
        "function(ament_add_test testname)\n  _ament_add_test(${testname} ${ARGN})\n"
        "endfunction()\n"
        "ament_add_test(t COMMAND true)\n",
    )
    include = f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    done = _configure(source, tmp_path / "build", env, include)
    assert done.returncode != 0, done.stdout
    message = " ".join(done.stderr.split())
    assert "ament_add_test(t) reached the wrapper of ros_isolated_test_all() twice" in message
    assert "CMAKE_PROJECT_INCLUDE called it, configure this package with " in message, message
    assert "-DROS_ISOLATED_TEST_ALL=OFF." in message, message
    _configured(source, tmp_path / "build", env, "-DROS_ISOLATED_TEST_ALL=OFF")
    runners = runners_of(tmp_path / "build" / "CTestTestfile.cmake")
    assert runners["t"].endswith("/ament_cmake_test/cmake/run_test.py"), runners


def test_no_runner_is_a_configure_error_naming_the_fix_and_the_opt_out(
    tmp_path: Path, env: dict[str, str], include_file: str
) -> None:
    source = _package(tmp_path / "src", "find_package(ament_cmake REQUIRED)\n")
    missing = tmp_path / "no-such-ros-isolated-test"
    include = f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    done = _configure(
        source, tmp_path / "build", env, include, f"-DROS_ISOLATED_TEST_EXECUTABLE={missing}"
    )
    assert done.returncode != 0, done.stdout
    message = " ".join(done.stderr.split())
    assert "ros_isolated_test (CMAKE_PROJECT_INCLUDE): cannot isolate the tests of tiny:" in message
    assert f"'{missing} runner-path' did not print the path of the RUNNER" in message, message
    assert "see Install it in its README" in message, message
    assert "configure without it: -DROS_ISOLATED_TEST_ALL=OFF" in message, message
    # The way out it names works.
    _configured(source, tmp_path / "build", env, "-DROS_ISOLATED_TEST_ALL=OFF")


# The colcon routes of the README, each with real colcon on a tiny workspace.


def _tiny_workspace(root: Path, env: Mapping[str, str]) -> Workspace:
    """Two quick ament_cmake packages, route_a and route_b, one test each."""
    for name in ("route_a", "route_b"):
        _package(
            root / "src" / name,
            "find_package(ament_cmake REQUIRED)\n"
            "ament_add_test(t COMMAND true GENERATE_RESULT_FOR_RETURN_CODE_ZERO)\n"
            "ament_package()\n",
            name=name,
        )
    return Workspace(root, env)


def _runner_of(ws: Workspace, package: str) -> str:
    return ws.runners(package)["t"]


def test_a_later_build_without_the_flag_keeps_it_and_minus_u_drops_it(
    tmp_path: Path, env: dict[str, str], runner_script: str
) -> None:
    ws = _tiny_workspace(tmp_path, env)
    ws.shell(RECIPE)
    assert _runner_of(ws, "route_a") == _runner_of(ws, "route_b") == runner_script
    ws.shell("colcon build")  # reconfigured (other arguments), from the cache
    assert ISOLATED.findall(ws.build_log("route_a")) == [("route_a", runner_script)]
    assert _runner_of(ws, "route_a") == runner_script
    ws.shell("colcon build --cmake-args -UCMAKE_PROJECT_INCLUDE")
    assert _runner_of(ws, "route_a").endswith("/ament_cmake_test/cmake/run_test.py")
    ws.shell("colcon build")
    assert _runner_of(ws, "route_a").endswith("/ament_cmake_test/cmake/run_test.py")
    assert not ISOLATED.findall(ws.build_log("route_a"))


@capabilities.CTEST.mark
def test_a_colcon_defaults_file_isolates_every_build(
    tmp_path: Path, pool_env: dict[str, str], runner_script: str
) -> None:
    """COLCON_DEFAULTS_FILE: every package isolated, its tests run on our IDs; a
    --cmake-args on the command line replaces the file's list (the control)."""
    ws = _tiny_workspace(tmp_path, pool_env)
    ws.shell("ros-isolated-test cmake-include --colcon-defaults > isolated.yaml")
    ws.env["COLCON_DEFAULTS_FILE"] = str(tmp_path / "isolated.yaml")
    ws.shell("colcon build")
    assert _runner_of(ws, "route_a") == _runner_of(ws, "route_b") == runner_script
    ws.shell("colcon test --parallel-workers 2")
    for name in ("route_a", "route_b"):
        text = (ws.root / "build" / name / "test_results" / name / "t.xml").read_text()
        assert re.search(r'<property name="ros_domain_id" value="\d+"', text), text
    ws.shell("colcon build --build-base other-build --cmake-args -DBUILD_TESTING=ON")
    runners = runners_of(ws.root / "other-build" / "route_a" / "CTestTestfile.cmake")
    assert runners["t"].endswith("/ament_cmake_test/cmake/run_test.py"), runners


@capabilities.CTEST.mark
def test_the_include_is_added_to_a_workspaces_defaults_file_keeping_every_setting(
    tmp_path: Path, pool_env: dict[str, str], runner_script: str
) -> None:
    """A workspace's own .colcon/defaults.yaml, read with COLCON_HOME=.colcon: its merged
    install layout and CMake argument apply before (the control: colcon reads the file;
    nothing isolated) and after ``cmake-include --colcon-defaults FILE`` added the include,
    which now isolates every test too."""
    ws = _tiny_workspace(tmp_path, pool_env)
    ws.env["COLCON_HOME"] = str(tmp_path / ".colcon")
    defaults = tmp_path / ".colcon" / "defaults.yaml"
    defaults.parent.mkdir()
    original = (
        "# the workspace's own settings\n"
        "build:\n  merge-install: true\n  cmake-args: [-DKEEP_ME=yes]\n"
        "test:\n  merge-install: true\n"
    )
    defaults.write_text(original)

    def merged_and_kept() -> None:
        assert (tmp_path / "install" / "share" / "route_a").is_dir()
        assert not (tmp_path / "install" / "route_a").exists(), "not the merged layout"
        cache = _cache(tmp_path / "build" / "route_a")
        assert "KEEP_ME:UNINITIALIZED=yes" in cache, cache

    ws.shell("colcon build")
    merged_and_kept()
    assert _runner_of(ws, "route_a").endswith("/ament_cmake_test/cmake/run_test.py")

    said = ws.shell("ros-isolated-test cmake-include --colcon-defaults .colcon/defaults.yaml")
    assert said.endswith("added to build's cmake-args; every other setting kept\n"), said
    assert defaults.read_text().startswith(original.partition("cmake-args")[0])
    ws.shell("colcon build")
    merged_and_kept()
    assert _runner_of(ws, "route_a") == _runner_of(ws, "route_b") == runner_script
    ws.shell("colcon test --parallel-workers 2")
    for name in ("route_a", "route_b"):
        result = load_result(ws.root / "build" / name / "test_results" / name / "t.xml")
        assert result.properties.get("ros_domain_id"), result.properties


def test_a_colcon_meta_entry_opts_one_package_out(
    tmp_path: Path, env: dict[str, str], runner_script: str
) -> None:
    ws = _tiny_workspace(tmp_path, env)
    meta = {"names": {"route_b": {"cmake-args": ["-DROS_ISOLATED_TEST_ALL=OFF"]}}}
    (tmp_path / "colcon.meta").write_text(json.dumps(meta))
    ws.shell(RECIPE)
    assert _runner_of(ws, "route_a") == runner_script  # the control
    assert _runner_of(ws, "route_b").endswith("/ament_cmake_test/cmake/run_test.py")
    assert NOT_ISOLATED.format("route_b") in ws.build_log("route_b")


def test_an_installed_wheel_prints_its_own_include(tmp_path: Path, env: dict[str, str]) -> None:
    """pip install --prefix: its command prints the file under its own share/, which
    isolates with its own runner; with the files gone, one line says what is wrong (exit 2)."""
    wheel = build_wheel(tmp_path / "wheel")
    prefix = tmp_path / "installed"
    site = install_wheel(wheel, prefix)
    installed = {
        **env,
        "PATH": os.pathsep.join((str(prefix / "bin"), env["PATH"])),
        "PYTHONPATH": os.pathsep.join(filter(None, (site, env.get("PYTHONPATH")))),
    }
    command = str(prefix / "bin" / "ros-isolated-test")
    printed = subprocess.run(
        [command, "cmake-include"], env=installed, capture_output=True, text=True, check=False
    )
    expected = prefix / "share/ros_isolated_test/cmake/ros_isolated_test_project_include.cmake"
    assert (printed.returncode, printed.stdout.strip()) == (0, str(expected)), printed.stderr
    source = _package(
        tmp_path / "src", "find_package(ament_cmake REQUIRED)\nament_add_test(t COMMAND true)\n"
    )
    _configured(source, tmp_path / "build", installed, f"-DCMAKE_PROJECT_INCLUDE={expected}")
    runner = Path(site) / "ros_isolated_test" / "ament" / "run_test_isolated.py"
    assert runners_of(tmp_path / "build" / "CTestTestfile.cmake") == {"t": str(runner)}

    # The wheel also has them in the package (setuptools' package data): the next place.
    shutil.rmtree(prefix / "share" / "ros_isolated_test")
    fallback = subprocess.run(
        [command, "cmake-include"], env=installed, capture_output=True, text=True, check=False
    )
    assert fallback.stdout.strip() == str(
        Path(site) / "ros_isolated_test" / "cmake" / expected.name
    )
    shutil.rmtree(Path(site) / "ros_isolated_test" / "cmake")
    broken = subprocess.run(
        [command, "cmake-include"], env=installed, capture_output=True, text=True, check=False
    )
    assert broken.returncode == 2 and not broken.stdout, broken
    assert broken.stderr.splitlines() == [
        "ros-isolated-test: error: the CMake files are not installed "
        "(share/ros_isolated_test/cmake/ros_isolated_test_project_include.cmake beside this "
        "package); reinstall ros-isolated-test with pip"
    ], broken.stderr


def test_a_package_with_an_old_minimum_version_is_isolated_too(
    tmp_path: Path, env: dict[str, str], include_file: str, runner_script: str
) -> None:
    """Our functions run under the package's own policies: one that asks for CMake 3.0
    (no IN_LIST, CMP0057) configures and is isolated; the control asks for 3.15."""
    body = "find_package(ament_cmake REQUIRED)\nament_add_test(t COMMAND true)\n"
    for minimum in ("3.0", "3.15"):
        source = _package(tmp_path / f"src-{minimum}", body, minimum=minimum)
        build = tmp_path / f"build-{minimum}"
        _configured(source, build, env, f"-DCMAKE_PROJECT_INCLUDE={include_file}")
        assert runners_of(build / "CTestTestfile.cmake") == {"t": runner_script}


def test_a_build_without_tests_isolates_a_test_registered_anyway(
    tmp_path: Path, env: dict[str, str], include_file: str, runner_script: str
) -> None:
    """BUILD_TESTING=OFF: a package whose tests are inside if(BUILD_TESTING) says nothing;
    an ament_add_test outside it (ctest runs it all the same) is isolated, and the line
    says so. With no runner to be found, a build not meant to test still configures and
    names that test as NOT isolated (with BUILD_TESTING ON it is a configure error:
    test_no_runner_is_a_configure_error_naming_the_fix_and_the_opt_out)."""
    include = f"-DCMAKE_PROJECT_INCLUDE={include_file}"
    no_runner = f"-DROS_ISOLATED_TEST_EXECUTABLE={tmp_path / 'no-such-ros-isolated-test'}"
    guarded = _package(
        tmp_path / "guarded",
        "find_package(ament_cmake REQUIRED)\n"
        "if(BUILD_TESTING)\n  ament_add_test(t COMMAND true)\nendif()\n",
    )
    stray = _package(
        tmp_path / "stray", "find_package(ament_cmake REQUIRED)\nament_add_test(t COMMAND true)\n"
    )
    for args in ((), (no_runner,)):
        quiet = _configured(guarded, tmp_path / f"guarded{len(args)}", env, include,
                            "-DBUILD_TESTING=OFF", *args)  # fmt: skip
        assert "ros_isolated_test:" not in quiet.stdout, quiet.stdout
        assert runners_of(tmp_path / f"guarded{len(args)}" / "CTestTestfile.cmake") == {}

    off = _configured(stray, tmp_path / "off", env, include, "-DBUILD_TESTING=OFF")
    assert runners_of(tmp_path / "off" / "CTestTestfile.cmake") == {"t": runner_script}
    (line,) = ISOLATED_LINE.findall(off.stdout)
    assert line.endswith(": 1 test (registered although BUILD_TESTING is OFF)"), off.stdout

    unfound = _configured(stray, tmp_path / "unfound", env, include, "-DBUILD_TESTING=OFF",
                          no_runner)  # fmt: skip
    runners = runners_of(tmp_path / "unfound" / "CTestTestfile.cmake")
    assert runners["t"].endswith("/ament_cmake_test/cmake/run_test.py"), runners
    said = " ".join(unfound.stdout.split())
    assert (
        "ros_isolated_test: NOT isolated, tests of tiny registered although BUILD_TESTING is "
        f"OFF: t; no runner was found: '{tmp_path / 'no-such-ros-isolated-test'} runner-path' "
        "did not print the path of the RUNNER script"
    ) in said, said
