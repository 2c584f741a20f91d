"""End to end: the crosstalk_demo ament_cmake package, built and tested with real colcon.

Six rclpy tests publish on one topic at once (ctest -j6). Through our runner each must get
its own ROS_DOMAIN_ID and pass; through ament's plain run_test.py (the control) the same
tests must fail, which is what shows the passes come from isolation and not from luck.
The workspace helpers are the demo's own (examples/crosstalk_workspace.py), loaded by path;
the package is built once per session (the ``crosstalk_builds`` fixture). The whole module
runs on each supported distro (the ``distro`` fixture): on Jazzy with the suite's own venv,
on Kilted with .venv-kilted's colcon, CMake prefix, Python and installed runner.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import pytest
from helpers import capabilities
from helpers.distros import Distro, Tools
from helpers.workspace import CrosstalkBuilds

if TYPE_CHECKING:  # for annotations only; at run time the module is loaded by path
    from examples.crosstalk_workspace import Record, Run


pytestmark = [pytest.mark.colcon, capabilities.COLCON.mark]


@pytest.fixture(scope="module")
def isolated_run(crosstalk_builds: CrosstalkBuilds, distro: Distro) -> Run:
    return crosstalk_builds.test("isolated", distro=distro)


@pytest.fixture(scope="module")
def plain_run(crosstalk_builds: CrosstalkBuilds, distro: Distro) -> Run:
    return crosstalk_builds.test("plain", distro=distro)


def _records(run: Run) -> list[Record]:
    missing = [c.name for c in run.cases if c.record is None]
    assert not missing, f"no record from {missing}:\n{run.test_output}"
    return [c.record for c in run.cases if c.record is not None]


def test_isolated_all_six_pass(isolated_run: Run) -> None:
    records = _records(isolated_run)
    assert len(records) == 6
    failed = {r.token: r.foreign for r in records if not r.passed}
    assert not failed, f"crosstalk despite isolation: {failed}"
    assert all(r.own_received > 0 for r in records)


def test_isolated_domain_ids_distinct_and_nonzero(isolated_run: Run) -> None:
    ids = [r.domain_id for r in _records(isolated_run)]
    assert None not in ids, f"a test ran without ROS_DOMAIN_ID: {ids}"
    assert len(set(ids)) == 6, f"domain IDs shared: {ids}"
    assert all(int(i) > 0 for i in ids if i is not None), f"domain 0 handed out: {ids}"


def test_isolated_tests_ran_at_the_same_time(isolated_run: Run) -> None:
    records = _records(isolated_run)
    for a, b in itertools.combinations(records, 2):
        assert a.start < b.end and b.start < a.end, (
            f"{a.token} and {b.token} did not overlap: "
            f"[{a.start:.2f}, {a.end:.2f}] vs [{b.start:.2f}, {b.end:.2f}]"
        )


def test_isolated_colcon_test_result_clean(isolated_run: Run) -> None:
    result = isolated_run.result
    assert result.returncode == 0, result.line
    assert (result.errors, result.failures) == (0, 0), result.line
    assert result.tests >= 6, result.line


def test_plain_control_fails_with_crosstalk(plain_run: Run) -> None:
    records = _records(plain_run)
    assert all(r.domain_id in (None, "0") for r in records)
    heard = [r for r in records if not r.passed and r.foreign]
    assert len(heard) >= 4, (
        f"only {len(heard)} of 6 tests heard crosstalk on a shared domain; the control is "
        f"too weak to prove anything:\n{plain_run.test_output}"
    )


def test_plain_colcon_test_result_reports_failures(plain_run: Run) -> None:
    result = plain_run.result
    assert result.returncode != 0, result.line
    assert result.failures + result.errors >= 4, result.line


def _registered(run: Run, python: str, runner: str) -> int:
    """How many tests ctest runs as ``<python> -u <runner> ... --command <python> ...``."""
    text = (run.base / "build" / "crosstalk_demo" / "CTestTestfile.cmake").read_text()
    return sum(
        1
        for line in text.splitlines()
        if line.startswith("add_test(")
        and f'"{python}" "-u" "{runner}" ' in line
        and f'"--command" "{python}" ' in line
    )


def test_both_builds_run_on_the_distros_python_and_runners(
    isolated_run: Run, plain_run: Run, tools: Tools, distro_runner_script: str
) -> None:
    """What ctest ran is the distro's own: its Python, our runner as its venv has it, its ament.

    Without this the Kilted passes could come from Jazzy's interpreter or libraries.
    """
    assert isolated_run.runner_path == distro_runner_script
    assert _registered(isolated_run, tools.python, distro_runner_script) == 6, tools
    plain = tools.distro.prefix / "share" / "ament_cmake_test" / "cmake" / "run_test.py"
    assert plain_run.runner_path == str(plain)
    assert _registered(plain_run, tools.python, str(plain)) == 6, tools
