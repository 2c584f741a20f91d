"""Launch files under pytest: isolated by the plugin and reported case by case (issue 24).

launch_testing's own pytest plugin reports a launch file as one test; under ours, each
``unittest`` case of it is a result of its own, the launch run once per file (per
parameter set), and each pytest session still on a ROS_DOMAIN_ID of its own. Real
launch_testing (the outside tier's vendored Jazzy sources, in the launch environment of
helpers/launch_env.py), real rclpy talkers, real colcon, pytest-xdist and ctest; the
control runs the same files with ``-p no:ros_isolated_test`` and must hear crosstalk.
The fallback, for a launch_testing whose insides differ, runs a stand-in launch_testing
(helpers/launch_files.py) with this suite's own pytest: what it checks is the plugin's
reading of launch_testing, which no real version here differs in.

launch_pytest (one pytest item per test already) is not among the vendored sources: the
plugin only ever replaces launch_testing's items, and the combined run shows an ordinary
pytest test beside the launch files left as it is, on the worker's ID.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from helpers import capabilities, launch_env, launch_files
from helpers.commands import HUNG, POLICY_VARS, normalise, run_cli
from helpers.domains import free_ids
from helpers.launch_files import ALWAYS_FAILS, TOKEN_CASES
from helpers.results import CaseResult, load_result
from helpers.workspace import crosstalk_workspace
from lxml import etree

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Record, ResultSummary

#: The two ament_python packages tested at once, by their talker's token.
PACKAGES = {"alpha": "launch_cases_alpha", "beta": "launch_cases_beta"}
OFF = ("-p", "no:ros_isolated_test")
#: Only stops a hung colcon; no verdict depends on it.
COLCON_HUNG = HUNG * 4


@pytest.fixture(scope="module")
def launch_python() -> Path:
    """The launch tier's own environment (built once, then kept in ``.venv-launch/``)."""
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


def _run_in(
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


# --- two ament_python packages, tested at once by colcon ---------------------------------


@dataclass(frozen=True)
class Workspace:
    root: Path
    env: dict[str, str]
    colcon: list[str]  # the launch environment's colcon with this workspace's folders

    def test(self, *extra: str) -> tuple[Run, ResultSummary]:
        """``colcon test`` of both packages at once, and colcon test-result's totals."""
        junit = {token: self.root / "build" / name / "pytest.xml" for token, name in
                 PACKAGES.items()}  # fmt: skip
        argv = [*self.colcon, "test", *self.paths, "--parallel-workers", "2", *extra]
        run = _run_in(self.root, self.env, argv, junit, self.root)
        ws = crosstalk_workspace()
        prefix = Path(self.colcon[0]).parents[1]
        toolchain = ws.Toolchain(python=str(prefix / "bin" / "python"), prefix=str(prefix))
        return run, ws.result_summary(self.root, toolchain)

    @property
    def paths(self) -> list[str]:
        return ["--base-paths", str(self.root / "src"), "--build-base", str(self.root / "build"),
                "--install-base", str(self.root / "install")]  # fmt: skip


@pytest.fixture(scope="module")
def python_workspace(launch_python: Path, tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """Both ament_python packages, built once with the launch environment's colcon."""
    root = tmp_path_factory.mktemp("launch-cases-python")
    for token, name in PACKAGES.items():
        launch_files.python_package(root / "src", name, token)
    env = launch_environment(launch_python, root, pool=2)
    colcon = [str(launch_python.parent / "colcon"), "--log-base", str(root / "log")]
    workspace = Workspace(root, env, colcon)
    build = subprocess.run(
        [*colcon, "build", *workspace.paths], cwd=root, env=env, capture_output=True,
        text=True, timeout=COLCON_HUNG, check=False,
    )  # fmt: skip
    assert build.returncode == 0, f"colcon build failed:\n{build.stdout}{build.stderr}"
    return workspace


@pytest.fixture(scope="module")
def isolated_run(python_workspace: Workspace) -> tuple[Run, ResultSummary]:
    return python_workspace.test()


@pytest.fixture(scope="module")
def plain_run(python_workspace: Workspace) -> tuple[Run, ResultSummary]:
    return python_workspace.test("--pytest-args", *OFF)


def _talkers(run: Run) -> list[Record]:
    missing = sorted(set(PACKAGES) - set(run.records))
    assert not missing, f"no talker record from {missing}:\n{run.output}"
    return [run.records[token] for token in PACKAGES]


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
    talkers = _talkers(run)
    assert all(record.passed for record in talkers), {r.token: r.foreign for r in talkers}
    ids = {record.token: record.domain_id for record in talkers}
    assert None not in ids.values() and len(set(ids.values())) == 2, f"IDs shared: {ids}"
    alpha, beta = talkers
    assert alpha.start < beta.end and beta.start < alpha.end, "the packages did not overlap"


@pytest.mark.ros
@pytest.mark.colcon
def test_without_the_plugin_the_same_files_hear_crosstalk(
    plain_run: tuple[Run, ResultSummary],
) -> None:
    """The control: one domain for both, crosstalk, and one test per file as before."""
    run, summary = plain_run
    talkers = _talkers(run)
    assert all(record.domain_id is None for record in talkers), [r.domain_id for r in talkers]
    heard = [record.token for record in talkers if record.foreign]
    assert heard, f"no crosstalk on one shared domain: the control proves nothing\n{run.output}"
    for token, name in PACKAGES.items():
        assert raw_cases(run.junit[token]) == {f"test_{token}_launch": "failure"}, name
    assert summary.tests == 2 and summary.failures == 2, summary.line


# --- one pytest -n 2 run: parameter sets, launches that cannot start, every outcome -------

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
    package = root / SUITE_PACKAGE
    (package / "test").mkdir(parents=True)
    (package / "pytest.ini").write_text("[pytest]\n")
    (package / "package.xml").write_text(
        launch_files.PACKAGE_XML.format(name=SUITE_PACKAGE, depends="", build_type="ament_python")
    )
    for name, text in SUITE.items():
        (package / "test" / name).write_text(text)
    env = launch_environment(launch_python, root, pool=2)
    junit = root / "junit.xml"
    argv = [str(launch_python), "-m", "pytest", "-p", "no:cacheprovider", "-n", "2", "-rA",
            f"--junit-xml={junit}", "test"]  # fmt: skip
    run = _run_in(root, env, argv, {"suite": junit}, package)
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


# --- the CMake routes: our pytest macro, ament's under ros_isolated_test_all(), add_launch_test


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
    return _run_in(root, env, argv, junit, root)


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


# --- a launch_testing whose insides differ: today's one test per file, one warning --------

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
    return _run_in(root, run_env, argv, {"junit": junit}, project)


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


@pytest.mark.ros
def test_a_rerun_case_launches_its_file_again(launch_python: Path, tmp_path: Path) -> None:
    """pytest-rerunfailures: the second try of a case gets a launch of its own."""
    package = tmp_path / "flaky"
    (package / "test").mkdir(parents=True)
    (package / "pytest.ini").write_text("[pytest]\n")
    (package / "package.xml").write_text(
        launch_files.PACKAGE_XML.format(name="flaky", depends="", build_type="ament_python")
    )
    (package / "test" / "test_flaky_launch.py").write_text(launch_files.FLAKY_LAUNCH)
    env = launch_environment(launch_python, tmp_path, pool=1)
    junit = tmp_path / "junit.xml"
    argv = [str(launch_python), "-m", "pytest", "-p", "no:cacheprovider", "--reruns", "1",
            f"--junit-xml={junit}", "test"]  # fmt: skip
    run = _run_in(tmp_path, env, argv, {"junit": junit}, package)
    assert raw_cases(junit) == {
        "TestWhileRunning.test_second_launch_only": "passed",
        "TestWhileRunning.test_steady": "passed",
    }, run.output
    assert len(run.launches("flaky")) == 2, run.log
    assert run.returncode == 0, run.output
