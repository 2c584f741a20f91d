"""``launch_testing_cases`` through colcon and ctest: each case a result, each package on its
own ID.

Two ament_python packages of launch files tested at once by real colcon: each
``unittest`` case of a launch file is a result of its own in pytest's result file (and in
the canonical file the runner and ``report`` read), the launch run once per file, and each
package's session on a ROS_DOMAIN_ID of its own, so the real rclpy talkers never hear each
other. The control runs the same files with ``-p no:ros_isolated_test`` and must hear
crosstalk, one test per file as before. The CMake routes (our pytest macro, ament's under
ros_isolated_test_all(), add_launch_test) give the same cases, each test on its own ID.
Real launch_testing (the outside tier's vendored Jazzy sources, in the launch environment
of helpers/launch_env.py).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from helpers import launch_files, launch_runs
from helpers.commands import run_cli
from helpers.launch_files import ALWAYS_FAILS, TOKEN_CASES
from helpers.launch_runs import (
    COLCON_HUNG,
    Run,
    Workspace,
    build_workspace,
    canonical,
    launch_environment,
    raw_cases,
    run_launches,
)
from helpers.pytest_sessions import OFF
from helpers.results import CaseResult, load_result

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import ResultSummary


@pytest.fixture(scope="module")
def launch_python() -> Path:
    """The launch tier's own environment (built once, then kept in ``.venv-launch/``)."""
    return launch_runs.launch_python()


# --- two ament_python packages, tested at once by colcon -----------------------------------------

#: The two ament_python packages tested at once, by their talker's token.
PACKAGES = {"alpha": "launch_cases_alpha", "beta": "launch_cases_beta"}


@pytest.fixture(scope="module")
def python_workspace(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """Both ament_python packages, built once with the launch environment's colcon."""
    root = tmp_path_factory.mktemp("launch-cases-python")
    return build_workspace(root, PACKAGES, launch_files.python_package)


@pytest.fixture(scope="module")
def isolated_run(python_workspace: Workspace) -> tuple[Run, ResultSummary]:
    return python_workspace.test()


@pytest.fixture(scope="module")
def plain_run(python_workspace: Workspace) -> tuple[Run, ResultSummary]:
    return python_workspace.test("--pytest-args", *OFF)


@pytest.mark.ros
@pytest.mark.colcon
def test_two_packages_at_once_report_each_case_on_distinct_ids(
    isolated_run: tuple[Run, ResultSummary], python_workspace: Workspace, tmp_path: Path
) -> None:
    run, summary = isolated_run
    for token, name in PACKAGES.items():
        cases = raw_cases(run.junit[token])
        assert sorted(cases) == sorted(TOKEN_CASES), f"{name}: {cases}\n{run.output}"
        failed = [case for case, outcome in cases.items() if outcome != "passed"]
        assert failed == [ALWAYS_FAILS], f"{name}: {cases}\n{run.output}"
        # The canonical file (the runner's, `report`'s) keeps them, message and all.
        made = canonical(run.junit[token], name, python_workspace.env, tmp_path)
        kept = {case.name: case for case in made}
        assert kept[ALWAYS_FAILS].outcome == "failure", kept
        assert f"fails on purpose ({token})" in kept[ALWAYS_FAILS].message
        assert "Traceback (most recent call last)" in kept[ALWAYS_FAILS].text
        assert [kept[case].outcome for case in TOKEN_CASES[1:]] == ["passed"] * 3, kept
        # One launch; every case ran in the pytest process that launched it.
        (launch,) = run.launches(token)
        assert {line[-2] for line in run.cases(token)} == {launch[-2]}, run.log
        assert len(run.cases(token)) == 4, run.log
    assert (summary.tests, summary.errors, summary.failures, summary.skipped) == (8, 0, 2, 0), (
        f"{summary.line}\n{run.output}"
    )
    build = python_workspace.root / "build"
    report = run_cli(["report", "--json", str(build)], python_workspace.env)
    total = json.loads(report.stdout)["total"]
    assert (total["tests"], total["failures"], total["errors"]) == (8, 2, 0), report.stdout
    talkers = python_workspace.talkers(run)
    assert all(record.passed for record in talkers), {r.token: r.foreign for r in talkers}
    ids = {record.token: record.domain_id for record in talkers}
    assert None not in ids.values() and len(set(ids.values())) == 2, f"IDs shared: {ids}"
    alpha, beta = talkers
    assert alpha.start < beta.end and beta.start < alpha.end, "the packages did not overlap"


@pytest.mark.ros
@pytest.mark.colcon
def test_without_the_plugin_the_same_files_hear_crosstalk(
    plain_run: tuple[Run, ResultSummary], python_workspace: Workspace
) -> None:
    """The control: one domain for both, crosstalk, and one test per file as before."""
    run, summary = plain_run
    talkers = python_workspace.talkers(run)
    assert all(record.domain_id is None for record in talkers), [r.domain_id for r in talkers]
    heard = [record.token for record in talkers if record.foreign]
    assert heard, f"no crosstalk on one shared domain: the control proves nothing\n{run.output}"
    for token, name in PACKAGES.items():
        assert raw_cases(run.junit[token]) == {f"test_{token}_launch": "failure"}, name
    assert summary.tests == 2 and summary.failures == 2, summary.line


# --- the CMake routes: our pytest macro, ament's under ros_isolated_test_all(), add_launch_test --


CMAKE_PACKAGE = "launch_cases_cmake"


@pytest.fixture(scope="module")
def cmake_run(launch_python: Path, tmp_path_factory: pytest.TempPathFactory) -> Run:
    """One launch file registered three ways, built, and its three tests run at once."""
    root = tmp_path_factory.mktemp("launch-cases-cmake")
    launch_files.cmake_package(root / "src", CMAKE_PACKAGE)
    env = launch_environment(launch_python, root, pool=3)
    colcon = [str(launch_python.parent / "colcon"), "--log-base", str(root / "log")]
    paths = ["--base-paths", str(root / "src"), "--build-base", str(root / "build"),
             "--install-base", str(root / "install")]  # fmt: skip
    build = subprocess.run(
        [*colcon, "build", *paths, "--cmake-args", f"-DPython3_EXECUTABLE={launch_python}"],
        cwd=root, env=env, capture_output=True, text=True, timeout=COLCON_HUNG, check=False,
    )  # fmt: skip
    assert build.returncode == 0, f"colcon build failed:\n{build.stdout}{build.stderr}"
    results = root / "build" / CMAKE_PACKAGE / "test_results" / CMAKE_PACKAGE
    junit = {test: results / f"{test}.xunit.xml" for test in launch_files.CMAKE_TESTS}
    argv = [*colcon, "test", *paths, "--ctest-args", "-j3"]
    return run_launches(root, env, argv, junit, root)


def _case_name(case: CaseResult, test: str) -> str:
    """launch_testing's name of a case: add_launch_test's file names the class apart."""
    if test == "by_launch":  # classname <package>.<Class>, name <method>
        return f"{case.classname.rpartition('.')[2]}.{case.name}"
    return case.name  # pytest's: classname <package>.<module>, name <Class>.<method>


@pytest.mark.ros
@pytest.mark.colcon
def test_cmake_routes_give_the_same_cases_each_on_its_own_id(cmake_run: Run) -> None:
    names: dict[str, list[str]] = {}
    for test, token in launch_files.CMAKE_TESTS.items():
        result = load_result(cmake_run.junit[test])  # the runner's canonical file
        assert result.properties.get("ros_domain_id"), (test, result.properties)
        names[test] = sorted(_case_name(case, test) for case in result.cases)
        failed = [_case_name(case, test) for case in result.cases if case.outcome != "passed"]
        assert failed == [ALWAYS_FAILS], (test, result.cases, cmake_run.output)
        (case,) = [c for c in result.cases if c.outcome == "failure"]
        assert f"fails on purpose ({token})" in case.message + case.text, case
    assert names["by_macro"] == sorted(TOKEN_CASES), names
    assert names["by_all"] == names["by_macro"] == names["by_launch"], names
    talkers = [cmake_run.records[token] for token in launch_files.CMAKE_TESTS.values()]
    assert all(record.passed for record in talkers), {r.token: r.foreign for r in talkers}
    ids = {record.token: record.domain_id for record in talkers}
    assert None not in ids.values() and len(set(ids.values())) == 3, f"IDs shared: {ids}"
