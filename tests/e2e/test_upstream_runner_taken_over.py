"""Upstream's isolated runner named in a package, taken over by the zero-edit include.

The testing guide registers launch tests as ``add_launch_test(... RUNNER
"${ament_cmake_ros_DIR}/run_test_isolated.py")``. Two ament_cmake packages do exactly that
with the token launch file (helpers/launch_files.py: a real rclpy talker, a listener case,
a case that always fails), built in one workspace with the zero-edit recipe; a colcon.meta
entry opts the control package out (``-DROS_ISOLATED_TEST_ALL=OFF``), so it stays on
Jazzy's upstream runner as it would without the include. One ``colcon test``: the taken
test runs through ours (our result file, case by case, on the page's timeline, on the ID
its talker really used); the control keeps upstream's runner and raw file, on no
timeline. A second ``colcon test`` with ``ROS_DOMAIN_ID`` exported: ours refuses the taken
test, as it refuses any; upstream's runs the control on that ID without a word.

The taken package also registers three ``true`` tests that pin ROS_DOMAIN_ID (label
``pinned``, left out of those runs): on upstream's runner with ENV and with APPEND_ENV, both
kept there (named at configure time, run by upstream's runner), and on the default runner
with APPEND_ENV, which ours refuses naming APPEND_ENV, the option to edit.

Real launch_testing (the outside tier's vendored Jazzy sources, in the launch environment
of helpers/launch_env.py), real colcon and ctest; one workspace build for the module.
"""

from __future__ import annotations

import json
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import capabilities, launch_files, launch_runs
from helpers.cmake_package import runners_of
from helpers.domains import free_ids
from helpers.launch_files import ALWAYS_FAILS, TOKEN_CASES
from helpers.launch_runs import COLCON_HUNG, Run, launch_environment, raw_cases, run_launches
from helpers.report_page import report_page, timeline_bars
from helpers.results import load_result

pytestmark = [pytest.mark.colcon, pytest.mark.ros, capabilities.OUTSIDE.mark]

#: The two packages by their talker's token: the one taken over, and the control.
TAKEN, KEPT = "taken", "kept"
PACKAGES = {TAKEN: "guide_taken", KEPT: "guide_kept"}
TARGET = "guide_launch"
#: The guide's registration, word for word but the token.
CMAKE_LISTS = """\
cmake_minimum_required(VERSION 3.20)
project({name} NONE)

find_package(ament_cmake REQUIRED)

if(BUILD_TESTING)
  find_package(ament_cmake_ros REQUIRED)
  find_package(launch_testing_ament_cmake REQUIRED)
  add_launch_test(test/test_tokens_launch.py TARGET {target}
    RUNNER "${{ament_cmake_ros_DIR}}/run_test_isolated.py"
    ENV LAUNCH_CASES_TOKEN={token} TIMEOUT 120){pinned}
endif()

ament_package()
"""
#: The taken package's tests that pin ROS_DOMAIN_ID: {id} is the pinned ID.
PINNED = """
  set(_upstream "${{ament_cmake_ros_DIR}}/run_test_isolated.py")
  ament_add_test(pinned_env COMMAND true RUNNER "${{_upstream}}" ENV ROS_DOMAIN_ID={id}
    GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
  ament_add_test(pinned_append COMMAND true RUNNER "${{_upstream}}"
    APPEND_ENV ROS_DOMAIN_ID={id} GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
  ament_add_test(appended COMMAND true APPEND_ENV ROS_DOMAIN_ID={id}
    GENERATE_RESULT_FOR_RETURN_CODE_ZERO)
  set_tests_properties(pinned_env pinned_append appended PROPERTIES LABELS pinned)"""
_RUNNING = re.compile(r"^Running with ROS_DOMAIN_ID (\d+)\b", re.MULTILINE)


def _package(root: Path, name: str, token: str, pinned: str = "") -> None:
    lists = CMAKE_LISTS.format(name=name, target=TARGET, token=token, pinned=pinned)
    depends = ("ament_cmake_ros", "launch_testing_ament_cmake", "rclpy")
    launch_files.cmake_package(root, name, lists, token, depends)


@dataclass(frozen=True)
class Workspace:
    root: Path
    env: dict[str, str]
    colcon: list[str]  # the launch environment's colcon with this workspace's log base
    build_output: str
    pinned: int  # the ID the taken package's pinned tests set

    @property
    def paths(self) -> list[str]:
        return ["--base-paths", str(self.root / "src"), "--build-base", str(self.root / "build"),
                "--install-base", str(self.root / "install")]  # fmt: skip

    def result(self, token: str) -> Path:
        name = PACKAGES[token]
        return self.root / "build" / name / "test_results" / name / f"{TARGET}.xunit.xml"

    def output(self, token: str) -> str:
        """What ctest kept of the test's output (the runner's first line among it)."""
        name = PACKAGES[token]
        log = self.root / "build" / name / "launch_test" / f"{TARGET}.txt"
        return log.read_text(errors="replace") if log.is_file() else ""

    def build_log(self, token: str) -> str:
        return (self.root / "log" / "latest_build" / PACKAGES[token] / "stdout.log").read_text()

    def test(self, **extra_env: str) -> Run:
        """``colcon test`` of both packages at once (the pinned tests left out)."""
        argv = [*self.colcon, "test", *self.paths, "--parallel-workers", "2",
                "--ctest-args", "-LE", "pinned"]  # fmt: skip
        junit = {token: self.result(token) for token in PACKAGES}
        return run_launches(self.root, {**self.env, **extra_env}, argv, junit, self.root)


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """Both packages, built once with the recipe; the control opted out by colcon.meta."""
    python = launch_runs.launch_python()
    root = tmp_path_factory.mktemp("upstream-runner")
    (pinned,) = free_ids(1)
    for token, name in PACKAGES.items():
        _package(root / "src", name, token, PINNED.format(id=pinned) if token == TAKEN else "")
    meta = {"names": {PACKAGES[KEPT]: {"cmake-args": ["-DROS_ISOLATED_TEST_ALL=OFF"]}}}
    (root / "colcon.meta").write_text(json.dumps(meta))
    env = launch_environment(python, root, pool=4)
    bin_dir = python.parent
    include = subprocess.run(
        [str(bin_dir / "ros-isolated-test"), "cmake-include"], env=env, capture_output=True,
        text=True, check=True,
    ).stdout.strip()  # fmt: skip
    colcon = [str(bin_dir / "colcon"), "--log-base", str(root / "log")]
    ws = Workspace(root, env, colcon, "", pinned)
    build = subprocess.run(
        [*colcon, "build", *ws.paths, "--cmake-args", f"-DCMAKE_PROJECT_INCLUDE={include}",
         f"-DPython3_EXECUTABLE={python}"],
        cwd=root, env=env, capture_output=True, text=True, timeout=COLCON_HUNG, check=False,
    )  # fmt: skip
    assert build.returncode == 0, f"colcon build failed:\n{build.stdout}{build.stderr}"
    return Workspace(root, env, colcon, build.stdout + build.stderr, pinned)


@pytest.fixture(scope="module")
def isolated_run(workspace: Workspace) -> Run:
    return workspace.test()


@pytest.fixture(scope="module")
def preset_run(workspace: Workspace, isolated_run: Run) -> tuple[Run, int]:
    """After the first run (its files are read first): the same with ROS_DOMAIN_ID set."""
    (preset,) = free_ids(1)
    return workspace.test(ROS_DOMAIN_ID=str(preset)), preset


def _case_name(classname: str, name: str) -> str:
    """launch_testing's name of an add_launch_test case: classname <package>.<Class>."""
    return f"{classname.rpartition('.')[2]}.{name}"


def test_configuring_counts_the_test_taken_over(workspace: Workspace, runner_script: str) -> None:
    """The taken package's line counts it; the control says it is not isolated at all."""
    said = workspace.build_log(TAKEN)
    assert re.search(
        rf"^-- ros_isolated_test: tests of {PACKAGES[TAKEN]} are isolated, .* run by \S+ "
        r"\(CMAKE_PROJECT_INCLUDE; .*\): 2 tests, 1 of them taken over from upstream's "
        r"run_test_isolated\.py$",
        said,
        re.MULTILINE,
    ), said
    assert "ros_isolated_test: tests of guide_kept are NOT isolated" in workspace.build_log(KEPT)
    runners = {
        token: runners_of(workspace.root / "build" / name / "CTestTestfile.cmake")[TARGET]
        for token, name in PACKAGES.items()
    }
    assert Path(runners[TAKEN]).name == Path(runner_script).name == "run_test_isolated.py"
    assert runners[TAKEN].endswith("/ros_isolated_test/ament/run_test_isolated.py")
    assert runners[KEPT].endswith("/share/ament_cmake_ros/cmake/run_test_isolated.py"), runners


def test_the_taken_test_runs_through_ours_case_by_case_on_the_id_its_talker_used(
    isolated_run: Run, workspace: Workspace
) -> None:
    result = load_result(workspace.result(TAKEN))  # our canonical file, schema-checked
    domain = result.properties.get("ros_domain_id")
    assert domain and result.properties.get("runner_version"), result.properties
    cases = {_case_name(case.classname, case.name): case.outcome for case in result.cases}
    assert sorted(cases) == sorted(TOKEN_CASES), f"{cases}\n{isolated_run.output}"
    assert [case for case, outcome in cases.items() if outcome != "passed"] == [ALWAYS_FAILS]
    talker = isolated_run.records[TAKEN]
    assert talker.passed and talker.domain_id == domain, (talker, domain)
    assert _RUNNING.findall(workspace.output(TAKEN)) == [domain], workspace.output(TAKEN)


def test_the_control_keeps_upstreams_runner_and_its_raw_file(
    isolated_run: Run, workspace: Workspace
) -> None:
    """Upstream's runner ran it: launch_testing's own file, none of our properties, on
    an ID upstream chose, which is not ours (both talkers heard only their own token)."""
    text = workspace.result(KEPT).read_text()
    assert "ros_domain_id" not in text and "runner_version" not in text, text
    cases = raw_cases(workspace.result(KEPT))
    assert sorted(cases) == sorted(case.split(".")[1] for case in TOKEN_CASES), cases
    talker = isolated_run.records[KEPT]
    assert talker.passed and talker.domain_id, talker
    assert talker.domain_id != isolated_run.records[TAKEN].domain_id


def test_the_taken_test_is_on_the_pages_timeline_and_the_control_is_not(
    isolated_run: Run, workspace: Workspace, env: dict[str, str], tmp_path: Path
) -> None:
    page = report_page(env, tmp_path / "page.html", workspace.root / "build")
    bars = timeline_bars(page)
    tests = {bar.get("data-test") for bar in bars}
    assert len(bars) == 1 and all(PACKAGES[TAKEN] in str(test) for test in tests), tests
    domain = load_result(workspace.result(TAKEN)).properties["ros_domain_id"]
    assert bars[0].get("data-domain") == domain


def test_a_preset_id_is_refused_as_ours_refuses_it_while_upstream_uses_it(
    preset_run: tuple[Run, int], workspace: Workspace
) -> None:
    run, preset = preset_run
    case = load_result(workspace.result(TAKEN)).only
    assert case.outcome == "failure", case
    assert f"ROS_DOMAIN_ID is already set to '{preset}'" in case.text, case
    assert TAKEN not in run.records, "the refused test ran its talker"
    # The control, on upstream's runner, ran on the preset ID without a word.
    assert run.records[KEPT].domain_id == str(preset), run.records[KEPT]


@pytest.fixture(scope="module")
def pinned_run(workspace: Workspace, preset_run: tuple[Run, int]) -> str:
    """After the other runs: ``colcon test`` of the taken package's pinned tests alone."""
    done = subprocess.run(
        [*workspace.colcon, "test", *workspace.paths, "--packages-select", PACKAGES[TAKEN],
         "--ctest-args", "-L", "pinned"],
        cwd=workspace.root, env=workspace.env, capture_output=True, text=True,
        timeout=COLCON_HUNG, check=False,
    )  # fmt: skip
    return done.stdout + done.stderr


def test_upstreams_runner_pinned_by_env_or_append_env_is_kept_alike(
    workspace: Workspace, pinned_run: str
) -> None:
    """Both keep upstream's runner, each named at configure time with the keyword that
    pinned the ID, and upstream's runner ran both (its result file, none of ours); the
    control, registered beside them: APPEND_ENV on the default runner is ours."""
    name = PACKAGES[TAKEN]
    runners = runners_of(workspace.root / "build" / name / "CTestTestfile.cmake")
    upstream = runners["pinned_env"]
    assert upstream.endswith("/share/ament_cmake_ros/cmake/run_test_isolated.py"), runners
    assert runners["pinned_append"] == upstream, runners
    assert runners["appended"].endswith("/ros_isolated_test/ament/run_test_isolated.py")
    said = workspace.build_log(TAKEN)
    (left_out,) = re.findall(r"ros_isolated_test: NOT isolated, .*$", said, re.MULTILINE)
    for test, keyword in (("pinned_env", "ENV"), ("pinned_append", "APPEND_ENV")):
        assert (
            f"{test} (upstream's run_test_isolated.py, kept: its {keyword} sets ROS_DOMAIN_ID)"
        ) in left_out, left_out
        result = workspace.root / "build" / name / "test_results" / name / f"{test}.xml"
        assert "ros_domain_id" not in result.read_text(), pinned_run[-3000:]


def test_an_id_appended_on_our_runner_is_refused_naming_append_env(
    workspace: Workspace, pinned_run: str
) -> None:
    name = PACKAGES[TAKEN]
    case = load_result(workspace.root / "build" / name / "test_results" / name / "appended.xml")
    assert case.only.outcome == "failure", pinned_run[-3000:]
    assert case.only.message.startswith(
        f"refusing to run: ROS_DOMAIN_ID='{workspace.pinned}' is passed with --append-env "
        "(ament_add_test APPEND_ENV), so the test would share that domain"
    ), case.only.message
