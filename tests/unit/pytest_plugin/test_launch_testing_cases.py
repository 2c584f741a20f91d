"""``launch_testing_cases``: launch_testing files under pytest, reported case by case (issue 24).

launch_testing's own pytest plugin reports a launch file as one test; under ours, each
``unittest`` case of it is a result of its own, the launch run once per file (per
parameter set): the first case to run launches it, a rerun of a case
(pytest-rerunfailures) launches it again. Where launch_testing's insides differ, the file
stays the one test launch_testing made, with one warning per session, and the run goes on:
this fallback runs a stand-in launch_testing (helpers/launch_files.py) with this suite's
own pytest, since what it checks is the plugin's reading of launch_testing, which no real
version here differs in; its positive control is the stand-in shaped as expected, split
case by case. The rerun runs real launch_testing (the outside tier's vendored Jazzy
sources, in the launch environment of helpers/launch_env.py). Routes through colcon and
ctest are tests/e2e/test_launch_testing_colcon.py's, one pytest -n 2 session of every
kind of launch file test_launch_testing_cases_xdist.py's; the reading of unittest's
records is test_launch_testing_verdicts.py's, xdist's unit of work test_scheduling.py's.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path

import pytest
from helpers import launch_files, launch_runs
from helpers.launch_runs import (
    Run,
    ament_python_package,
    launch_environment,
    raw_cases,
    run_launches,
)


@pytest.fixture(scope="module")
def launch_python() -> Path:
    """The launch tier's own environment (built once, then kept in ``.venv-launch/``)."""
    return launch_runs.launch_python()


# --- a launch_testing whose insides differ: today's one test per file, one warning ---------------

WARNING = "ros-isolated-test: launch_testing 0.0.1 is not as expected"


def fake_run(root: Path, env: Mapping[str, str], shape: str, *args: str) -> Run:
    """This suite's pytest over FAKE_LAUNCH_FILES with the stand-in launch_testing."""
    site = launch_files.fake_launch_testing(root)
    project = root / "project"
    project.mkdir()
    (project / "pytest.ini").write_text("[pytest]\n")
    for name, text in launch_files.FAKE_LAUNCH_FILES.items():
        (project / name).write_text(text)
    junit = root / "junit.xml"
    run_env = {**env, "PYTHONPATH": str(site), "FAKE_LAUNCH_TESTING_SHAPE": shape}
    argv = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-rA",
            f"--junit-xml={junit}", *args, "."]  # fmt: skip
    return run_launches(root, run_env, argv, {"junit": junit}, project)


def test_a_launch_testing_shaped_as_expected_is_reported_case_by_case(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """The positive control of the fallback: the stand-in, as expected, is split."""
    run = fake_run(tmp_path, env, "expected")
    assert raw_cases(run.junit["junit"]) == {
        "TestMixed.test_bad": "failure",
        "TestMixed.test_good": "passed",
        "TestFine.test_fine": "passed",
    }, run.output
    assert WARNING not in run.output
    assert run.returncode == 1, run.output


@pytest.mark.parametrize("werror", [(), ("-W", "error")], ids=["warnings", "warnings-as-errors"])
def test_a_launch_testing_that_differs_keeps_one_test_per_file_and_warns_once(
    tmp_path: Path, env: dict[str, str], werror: tuple[str, ...]
) -> None:
    """Its items hold their runs under another name: each file stays one test, as before."""
    run = fake_run(tmp_path, env, "renamed", *werror)
    assert raw_cases(run.junit["junit"]) == {
        "test_mixed_launch": "failure",
        "test_fine_launch": "passed",
    }, run.output
    assert run.output.count(WARNING) == 1, run.output
    assert "its test item has no list of test runs (test_runs)" in run.output
    assert run.returncode == 1, run.output  # the test's failure, never an internal error


def test_results_that_cannot_be_read_case_by_case_are_one_result_per_launch(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """Its results lack testCases: the launch's outcome on its first case, the rest skipped."""
    run = fake_run(tmp_path, env, "results")
    assert raw_cases(run.junit["junit"]) == {
        "TestMixed.test_bad": "failure",
        "TestMixed.test_good": "skipped",
        "TestFine.test_fine": "passed",
    }, run.output
    assert run.output.count(WARNING) == 1, run.output
    assert "its test result has no testCases" in run.output
    assert "bad on purpose" in run.output


# --- a rerun -------------------------------------------------------------------------------------


@pytest.mark.ros
def test_a_rerun_case_launches_its_file_again(launch_python: Path, tmp_path: Path) -> None:
    """pytest-rerunfailures: the second try of a case gets a launch of its own."""
    package = ament_python_package(tmp_path, "flaky")
    (package / "test" / "test_flaky_launch.py").write_text(launch_files.FLAKY_LAUNCH)
    env = launch_environment(launch_python, tmp_path, pool=1)
    junit = tmp_path / "junit.xml"
    argv = [str(launch_python), "-m", "pytest", "-p", "no:cacheprovider", "--reruns", "1",
            f"--junit-xml={junit}", "test"]  # fmt: skip
    run = run_launches(tmp_path, env, argv, {"junit": junit}, package)
    assert raw_cases(junit) == {
        "TestWhileRunning.test_second_launch_only": "passed",
        "TestWhileRunning.test_steady": "passed",
    }, run.output
    assert len(run.launches("flaky")) == 2, run.log
    assert run.returncode == 0, run.output
