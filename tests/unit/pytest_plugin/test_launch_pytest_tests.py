"""``launch_pytest_tests``: launch_pytest files under ``pytest -n 2``, each test as itself.

launch_pytest files in one ROS package, run by real pytest-xdist with real launch_pytest
(the outside tier's vendored Jazzy sources, in the launch environment of
helpers/launch_env.py) and real rclpy talkers over Fast DDS on one topic: each token
file runs on one worker, launched once, on that worker's own ID, and every test is a
result of its own, the post-shutdown half of a generator test under its own name. A
launch that cannot start, or a launch fixture that raises, is one error, the other tests
skipped, none passed; a launch that fails after its tests began is one error at its end.
Controls: the same token files without the plugin hear each other (one domain); the
launch fixture that raises is an error of each test, and the launch that fails later a
clean pass, as launch_pytest alone reports them. The same through colcon is
tests/e2e/test_launch_pytest_colcon.py's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import launch_pytest_files, launch_runs
from helpers.launch_pytest_files import ALWAYS_FAILS, TOKEN_TESTS
from helpers.launch_runs import (
    Run,
    ament_python_package,
    canonical,
    launch_environment,
    raw_cases,
    run_launches,
)
from helpers.pytest_sessions import OFF
from helpers.results import CaseResult

PACKAGE = "launch_pytest_suite"
TOKENS = ("gamma", "delta")
#: The files of the combined run, by file name.
SUITE = {
    **{f"test_{token}_launch.py": launch_pytest_files.token_file(token) for token in TOKENS},
    "test_cannot_start_launch.py": launch_pytest_files.CANNOT_START_FILE,
    "test_broken_launch.py": launch_pytest_files.BROKEN_FILE,
    "test_fails_later_launch.py": launch_pytest_files.FAILS_LATER_FILE,
}


@dataclass(frozen=True)
class Suite:
    run: Run
    package: Path
    env: dict[str, str]
    cases: dict[str, CaseResult]  # canonical, by "module::name"

    def outcomes(self, module: str) -> dict[str, str]:
        return {
            key.partition("::")[2]: case.outcome
            for key, case in self.cases.items()
            if key.startswith(f"{module}::")
        }


def _pytest(python: Path, *args: str) -> list[str]:
    return [str(python), "-m", "pytest", "-p", "no:cacheprovider", "-rA", *args]


@pytest.fixture(scope="module")
def suite(tmp_path_factory: pytest.TempPathFactory) -> Suite:
    """Every file of SUITE in one ``pytest -n 2`` session, inside a ROS package."""
    python = launch_runs.launch_python()
    root = tmp_path_factory.mktemp("launch-pytest-suite")
    package = ament_python_package(root, PACKAGE)
    for name, text in SUITE.items():
        (package / "test" / name).write_text(text)
    env = launch_environment(python, root, pool=2)
    junit = root / "junit.xml"
    argv = _pytest(python, "-n", "2", f"--junit-xml={junit}", "test")
    run = run_launches(root, env, argv, {"suite": junit}, package)
    by_file = {}
    for case in canonical(junit, PACKAGE, env, root / "canonical"):
        module = case.classname.removeprefix(f"{PACKAGE}.").removeprefix("test.")
        by_file[f"{module}::{case.name}"] = case
    return Suite(run, package, env, by_file)


@pytest.mark.ros
def test_each_token_file_on_one_worker_and_its_own_id_every_test_as_itself(suite: Suite) -> None:
    run = suite.run
    for token in TOKENS:
        outcomes = suite.outcomes(f"test_{token}_launch")
        assert sorted(outcomes) == sorted(TOKEN_TESTS), (token, outcomes, run.output)
        failed = [name for name, outcome in outcomes.items() if outcome != "passed"]
        assert failed == [ALWAYS_FAILS], (token, outcomes, run.output)
        assert (
            f"fails on purpose ({token})"
            in suite.cases[f"test_{token}_launch::{ALWAYS_FAILS}"].message
        )
        # -rA as pytest shows them: the post-shutdown half under its own node ID.
        shown = f"PASSED test/test_{token}_launch.py::test_only_own_token[shutdown_test]"
        assert shown in run.output, run.output
        # One launch; every test ran in the pytest process that launched it, in order.
        (launch,) = run.launches(token)
        assert {line[-2] for line in run.cases(token)} == {launch[-2]}, run.log
        assert [line[2] for line in run.cases(token)] == list(TOKEN_TESTS), run.log
    talkers = [run.records[token] for token in TOKENS]
    assert all(record.passed for record in talkers), {r.token: r.foreign for r in talkers}
    ids = {record.token: record.domain_id for record in talkers}
    assert None not in ids.values() and len(set(ids.values())) == 2, f"IDs shared: {ids}"
    gamma, delta = talkers
    assert gamma.start < delta.end and delta.start < gamma.end, "the talkers did not overlap"


@pytest.mark.ros
@pytest.mark.parametrize(
    ("module", "token", "said"),
    [
        ("test_cannot_start_launch", "cannot-start", "ended before it was ready to test"),
        ("test_broken_launch", "broken", "FileNotFoundError: no such map: /maps/missing.yaml"),
    ],
)
def test_a_launch_that_cannot_start_is_one_error_and_no_test_passed(
    suite: Suite, module: str, token: str, said: str
) -> None:
    outcomes = suite.outcomes(module)
    assert outcomes == {
        "test_first": "error",
        "test_second": "skipped",
        "test_after": "skipped",
    }, (outcomes, suite.run.output)
    assert said in suite.cases[f"{module}::test_first"].message
    skipped = suite.cases[f"{module}::test_second"].message
    assert f"the one error is on test/{module}.py::test_first" in skipped, skipped
    assert suite.run.launches(token), suite.run.log  # it was launched ...
    assert suite.run.cases(token) == [], suite.run.log  # ... and no test ran


@pytest.mark.ros
def test_a_launch_that_fails_after_its_tests_began_is_one_error(suite: Suite) -> None:
    """Both tests ran and passed; the launch's failure is one error, at the teardown of its
    last test (pytest's result file holds it as that test's error)."""
    outcomes = suite.outcomes("test_fails_later_launch")
    assert outcomes == {"test_first": "passed", "test_second": "error"}, outcomes
    error = suite.cases["test_fails_later_launch::test_second"]
    assert "failed on teardown" in error.message, error
    assert "its launch service returned 1" in error.message, error
    assert [line[2] for line in suite.run.cases("fails-later")] == ["test_first", "test_second"]
    assert suite.run.returncode == 1, suite.run.output


@pytest.mark.ros
def test_control_without_the_plugin_the_token_files_hear_each_other(
    suite: Suite, tmp_path: Path
) -> None:
    """The same token files on one domain: crosstalk, the control for isolation. Each file
    on one worker as with the plugin (xdist's loadfile), so each talker runs to its end."""
    python = launch_runs.launch_python()
    files = [f"test/test_{token}_launch.py" for token in TOKENS]
    argv = _pytest(python, *OFF, "-n", "2", "--dist", "loadfile", *files)
    run = run_launches(tmp_path, suite.env, argv, {}, suite.package)
    talkers = [run.records[token] for token in TOKENS if token in run.records]
    assert len(talkers) == 2, run.output
    assert all(record.domain_id is None for record in talkers), [r.domain_id for r in talkers]
    heard = [record.token for record in talkers if record.foreign]
    assert heard, f"no crosstalk on one shared domain: the control proves nothing\n{run.output}"


@pytest.mark.ros
def test_control_launch_pytest_alone_reports_a_failed_launch_per_test_or_not_at_all(
    suite: Suite, tmp_path: Path
) -> None:
    """What the plugin sets right, as launch_pytest alone reports it: the launch fixture's
    error once per test, the launch that failed later a clean pass (exit 0)."""
    python = launch_runs.launch_python()
    junit = tmp_path / "junit.xml"
    argv = _pytest(python, *OFF, f"--junit-xml={junit}", "test/test_broken_launch.py")
    run = run_launches(tmp_path, suite.env, argv, {"junit": junit}, suite.package)
    assert set(raw_cases(junit).values()) == {"error"}, run.output
    assert len(raw_cases(junit)) == 3, run.output
    later = run_launches(
        tmp_path, suite.env, _pytest(python, *OFF, "test/test_fails_later_launch.py"), {},
        suite.package,
    )  # fmt: skip
    assert later.returncode == 0 and "2 passed" in later.output, later.output
