"""``launch_testing_cases`` under ``pytest -n 2``: parameter sets, failed launches, outcomes.

Every kind of launch file in one ROS package, run by real pytest-xdist with real
launch_testing (the outside tier's vendored Jazzy sources, in the launch environment of
helpers/launch_env.py) and real rclpy talkers: a ``launch_testing.parametrize`` file is
launched once per parameter set, its cases named with it; a launch that cannot start, or
stops before its tests finished, is one error and no case passed; every ``unittest``
outcome is a result with its own message; a launch file and its cases stay on one worker,
each worker on an ID of its own, and an ordinary pytest test beside them is left as it is.
launch_pytest's plugin is loaded too (one pytest item per test already): only
launch_testing's items are ever replaced; launch_pytest files are
test_launch_pytest_tests.py's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import launch_files, launch_runs
from helpers.launch_runs import (
    Run,
    ament_python_package,
    canonical,
    launch_environment,
    run_launches,
)
from helpers.results import CaseResult


@pytest.fixture(scope="module")
def launch_python() -> Path:
    """The launch tier's own environment (built once, then kept in ``.venv-launch/``)."""
    return launch_runs.launch_python()


#: The files of the combined run, by file name.
SUITE = {
    "test_gamma_launch.py": launch_files.token_launch("gamma"),
    "test_delta_launch.py": launch_files.token_launch("delta"),
    "test_param_launch.py": launch_files.PARAMETRIZED_LAUNCH,
    "test_cannot_start_launch.py": launch_files.CANNOT_START_LAUNCH,
    "test_dies_early_launch.py": launch_files.DIES_EARLY_LAUNCH,
    "test_broken_launch.py": launch_files.BROKEN_DESCRIPTION_LAUNCH,
    "test_outcomes_launch.py": launch_files.OUTCOMES_LAUNCH,
    "test_plain.py": launch_files.PLAIN_TEST,
}


SUITE_PACKAGE = "launch_suite"


@dataclass(frozen=True)
class Suite:
    run: Run
    cases: dict[str, CaseResult]  # canonical, by "file::case"


@pytest.fixture(scope="module")
def xdist_suite(launch_python: Path, tmp_path_factory: pytest.TempPathFactory) -> Suite:
    """Every launch file of SUITE in one ``pytest -n 2`` session, inside a ROS package."""
    root = tmp_path_factory.mktemp("launch-suite")
    package = ament_python_package(root, SUITE_PACKAGE)
    for name, text in SUITE.items():
        (package / "test" / name).write_text(text)
    env = launch_environment(launch_python, root, pool=2)
    junit = root / "junit.xml"
    argv = [str(launch_python), "-m", "pytest", "-p", "no:cacheprovider", "-n", "2", "-rA",
            f"--junit-xml={junit}", "test"]  # fmt: skip
    run = run_launches(root, env, argv, {"suite": junit}, package)
    kept = canonical(junit, SUITE_PACKAGE, env, root / "canonical")
    by_file = {}
    for case in kept:
        module = case.classname.removeprefix(f"{SUITE_PACKAGE}.").removeprefix("test.")
        by_file[f"{module}::{case.name}"] = case
    return Suite(run, by_file)


def _outcomes(suite: Suite, module: str) -> dict[str, str]:
    return {
        key.partition("::")[2]: case.outcome
        for key, case in suite.cases.items()
        if key.startswith(f"{module}::")
    }


@pytest.mark.ros
def test_parametrize_launches_once_per_parameter_set_with_its_name(xdist_suite: Suite) -> None:
    run = xdist_suite.run
    assert _outcomes(xdist_suite, "test_param_launch") == {
        "TestWhileRunning.test_is_red[red, 1]": "passed",
        "TestWhileRunning.test_is_red[blue, 2]": "failure",
        "TestWhileRunning.test_size[red, 1]": "passed",
        "TestWhileRunning.test_size[blue, 2]": "passed",
        "TestAfterShutdown.test_after[red, 1]": "passed",
        "TestAfterShutdown.test_after[blue, 2]": "passed",
    }, run.output
    failed = xdist_suite.cases["test_param_launch::TestWhileRunning.test_is_red[blue, 2]"]
    assert "'blue' != 'red'" in failed.message
    for colour in ("red", "blue"):
        (launch,) = run.launches(f"param-{colour}")
        assert [line[-2] for line in run.cases(f"param-{colour}")] == [launch[-2]] * 3, run.log


@pytest.mark.ros
@pytest.mark.parametrize(
    ("module", "token", "said"),
    [
        ("test_cannot_start_launch", "cannot-start", "the launch stopped before its active tests"),
        ("test_dies_early_launch", "dies-early", "the launch stopped before its active tests"),
        ("test_broken_launch", "broken", "FileNotFoundError: no such map: /maps/missing.yaml"),
    ],
)
def test_a_launch_that_cannot_start_is_one_error_and_no_case_passed(
    xdist_suite: Suite, module: str, token: str, said: str
) -> None:
    outcomes = _outcomes(xdist_suite, module)
    assert sorted(outcomes.values()).count("error") == 1, outcomes
    assert set(outcomes.values()) == {"error", "skipped"}, outcomes
    (error,) = [xdist_suite.cases[f"{module}::{name}"] for name, outcome in outcomes.items()
                if outcome == "error"]  # fmt: skip
    assert said in error.message, error
    assert xdist_suite.run.launches(token), xdist_suite.run.log  # it was launched ...
    assert xdist_suite.run.cases(token) == [], xdist_suite.run.log  # ... and no case ran


@pytest.mark.ros
def test_every_unittest_outcome_is_a_result_with_its_own_message(xdist_suite: Suite) -> None:
    outcomes = _outcomes(xdist_suite, "test_outcomes_launch")
    assert outcomes == {
        "TestOutcomes.test_error": "error",
        "TestOutcomes.test_failure": "failure",
        "TestOutcomes.test_passed": "passed",
        "TestOutcomes.test_skipped": "skipped",
        "TestOutcomes.test_subtests": "failure",
        "TestBrokenSetUp.test_never_runs": "error",
    }, xdist_suite.run.output

    def case(name: str) -> CaseResult:
        return xdist_suite.cases[f"test_outcomes_launch::{name}"]

    assert "RuntimeError: boom in test_error" in case("TestOutcomes.test_error").message
    assert "one is not two" in case("TestOutcomes.test_failure").message
    assert "in test_failure" in case("TestOutcomes.test_failure").text
    assert case("TestOutcomes.test_skipped").message == "skipped on purpose"
    subtests = case("TestOutcomes.test_subtests").text
    assert "subtest value 2" in subtests and "subtest value 3" in subtests, subtests
    assert "setUpClass could not open its device" in case("TestBrokenSetUp.test_never_runs").message


@pytest.mark.ros
def test_xdist_keeps_a_launch_file_and_its_cases_on_one_worker(xdist_suite: Suite) -> None:
    run = xdist_suite.run
    assert run.returncode == 1, run.output
    workers = set()
    for token in ("gamma", "delta", "param-red", "param-blue"):
        (launch,) = run.launches(token)  # once per file, per parameter set
        assert {line[-2] for line in run.cases(token)} == {launch[-2]}, run.log
        workers.add(launch[-2])
    (outcomes_launch,) = run.launches("outcomes")
    workers.add(outcomes_launch[-2])
    assert len(workers) == 2, f"the files ran in {len(workers)} pytest processes: {run.log}"
    # Each worker on an ID of its own: the talkers never heard each other.
    talkers = [run.records[token] for token in ("gamma", "delta")]
    assert all(record.passed for record in talkers), {r.token: r.foreign for r in talkers}
    ids = {line[-1] for line in run.log}
    assert len(ids) == 2 and "-" not in ids, ids
    # Cases are what pytest counts: in its summary, and an ordinary test is left as it is.
    assert _outcomes(xdist_suite, "test_plain") == {
        "test_plain_pytest_has_the_workers_id": "passed"
    }
    # launch's own warnings (two launches racing for its "latest" log link) may be there too.
    summary = run.output.rstrip().splitlines()[-1]
    counts = dict((word, int(n)) for n, word in re.findall(r"(\d+) (\w+)", summary))
    counts.pop("warning", None)
    counts.pop("warnings", None)
    assert counts == {"failed": 5, "passed": 13, "skipped": 5, "errors": 5}, run.output
