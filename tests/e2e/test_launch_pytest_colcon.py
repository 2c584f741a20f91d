"""launch_pytest files through colcon: two packages at once, each test a result, each on its ID.

Two ament_python packages whose tests are launch_pytest files, tested at once by real
colcon (``--parallel-workers 2``): every test of a file, active and post-shutdown alike,
is a result of its own in pytest's result file (and in the canonical file ``report``
reads), the launch run once per file, and each package's session on a ROS_DOMAIN_ID of
its own, so the real rclpy talkers never hear each other. The control runs the same
files with ``-p no:ros_isolated_test`` and must hear crosstalk. Real launch_pytest (the
outside tier's vendored Jazzy sources, in the launch environment of
helpers/launch_env.py); one workspace, built once for both runs.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import pytest
from helpers import launch_pytest_files
from helpers.commands import run_cli
from helpers.launch_pytest_files import ALWAYS_FAILS, TOKEN_TESTS
from helpers.launch_runs import (
    Workspace,
    build_workspace,
    raw_cases,
)
from helpers.pytest_sessions import OFF

if TYPE_CHECKING:  # annotations only; at run time the module is loaded by path
    pass

#: The two packages tested at once, by their talker's token.
PACKAGES = {"kappa": "launch_pytest_kappa", "sigma": "launch_pytest_sigma"}


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """Both packages, built once with the launch environment's colcon."""
    root = tmp_path_factory.mktemp("launch-pytest-colcon")
    return build_workspace(root, PACKAGES, launch_pytest_files.python_package)


@pytest.mark.ros
@pytest.mark.colcon
def test_two_packages_at_once_report_every_test_on_distinct_ids(workspace: Workspace) -> None:
    run, summary = workspace.test()
    for token, name in PACKAGES.items():
        tests = raw_cases(run.junit[token])
        assert sorted(tests) == sorted(TOKEN_TESTS), f"{name}: {tests}\n{run.output}"
        failed = [test for test, outcome in tests.items() if outcome != "passed"]
        assert failed == [ALWAYS_FAILS], f"{name}: {tests}\n{run.output}"
        # One launch; every test ran in the pytest process that launched it.
        (launch,) = run.launches(token)
        assert {line[-2] for line in run.cases(token)} == {launch[-2]}, run.log
        assert [line[2] for line in run.cases(token)] == list(TOKEN_TESTS), run.log
    assert (summary.tests, summary.errors, summary.failures, summary.skipped) == (10, 0, 2, 0), (
        f"{summary.line}\n{run.output}"
    )
    report = run_cli(["report", "--json", str(workspace.root / "build")], workspace.env)
    total = json.loads(report.stdout)["total"]
    assert (total["tests"], total["failures"], total["errors"]) == (10, 2, 0), report.stdout
    talkers = workspace.talkers(run)
    assert all(record.passed for record in talkers), {r.token: r.foreign for r in talkers}
    first, second = talkers
    assert first.start < second.end and second.start < first.end, "the packages did not overlap"
    ids = {record.token: record.domain_id for record in talkers}
    assert None not in ids.values() and len(set(ids.values())) == 2, f"IDs shared: {ids}"


@pytest.mark.ros
@pytest.mark.colcon
def test_control_without_the_plugin_the_same_files_hear_crosstalk(workspace: Workspace) -> None:
    run, _summary = workspace.test("--pytest-args", *OFF)
    talkers = workspace.talkers(run)
    assert all(record.domain_id is None for record in talkers), [r.domain_id for r in talkers]
    heard = [record.token for record in talkers if record.foreign]
    assert heard, f"no crosstalk on one shared domain: the control proves nothing\n{run.output}"
