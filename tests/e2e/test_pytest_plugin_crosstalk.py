"""``pytest_plugin`` against real crosstalk: colcon and xdist sessions on IDs of their own.

Real colcon over the ament_python packages of examples/python_tokens (built once per
session), and real rclpy token exchanges that fail on crosstalk: three packages tested at
once by colcon, and three xdist workers, each on an ID of its own, the ID named in
pytest's own result file. The control for each: the same run with
``-p no:ros_isolated_test`` shares domain 0 and fails.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Mapping
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import HUNG, POLICY_VARS, REPO
from helpers.pytest_sessions import OFF, run_pytest
from helpers.workspace import crosstalk_workspace

EXAMPLES = REPO / "examples" / "python_tokens"


ONE_TEST = ("python_tokens_dahlia", "python_tokens_ember", "python_tokens_fennel")


@pytest.fixture(scope="session")
def token_workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """examples/python_tokens built once with colcon: install/ holds the python_tokens module."""
    capabilities.require(capabilities.RCLPY, capabilities.COLCON)
    root = tmp_path_factory.mktemp("python-tokens")
    shutil.copytree(EXAMPLES, root / "src", ignore=shutil.ignore_patterns("__pycache__"))
    build = subprocess.run(
        ["colcon", "build", "--event-handlers", "console_direct-"],
        cwd=root,
        env=crosstalk_workspace().colcon_env(),
        capture_output=True,
        text=True,
        timeout=HUNG * 3,
        check=False,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    return root


@pytest.fixture
def ros_env(env: dict[str, str], tmp_path: Path) -> dict[str, str]:
    """colcon's environment, our own lock dir, records in tmp_path/records."""
    clean = {
        key: value
        for key, value in crosstalk_workspace().colcon_env().items()
        if key not in POLICY_VARS
    }
    clean["ROS_ISOLATED_TEST_LOCK_DIR"] = env["ROS_ISOLATED_TEST_LOCK_DIR"]
    clean["CROSSTALK_RECORD_DIR"] = str(tmp_path / "records")
    return clean


def records(tmp_path: Path) -> dict[str, dict[str, object]]:
    folder = tmp_path / "records"
    found = {path.stem: json.loads(path.read_text()) for path in folder.glob("*.json")}
    return found


def colcon_test(root: Path, env: Mapping[str, str], *extra: str) -> str:
    """``colcon test`` of the three one-test packages, three at once; colcon's summary."""
    subprocess.run(
        ["colcon", "test", "--packages-select", *ONE_TEST, "--parallel-workers", "3", *extra],
        cwd=root,
        env=dict(env),
        capture_output=True,
        timeout=HUNG * 2,
        check=False,
    )
    summary = subprocess.run(
        ["colcon", "test-result", "--all"],
        cwd=root,
        env=dict(env),
        capture_output=True,
        text=True,
        timeout=HUNG,
        check=False,
    )
    return summary.stdout


def clear_results(root: Path) -> None:
    for name in ONE_TEST:
        (root / "build" / name / "pytest.xml").unlink(missing_ok=True)


@pytest.mark.ros
@pytest.mark.colcon
def test_colcon_runs_three_ament_python_packages_on_three_ids(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    clear_results(token_workspace)
    summary = colcon_test(token_workspace, ros_env)
    assert "Summary: 3 tests, 0 errors, 0 failures, 0 skipped" in summary, summary
    found = records(tmp_path)
    assert sorted(found) == ["dahlia", "ember", "fennel"]
    ids = {str(record["domain_id"]) for record in found.values()}
    assert len(ids) == 3 and "None" not in ids, found
    # colcon's own result file (pytest's --junit-xml) names the ID as a suite property.
    for token in found:
        xml = (token_workspace / "build" / f"python_tokens_{token}" / "pytest.xml").read_text()
        assert f'<property name="ros_domain_id" value="{found[token]["domain_id"]}"' in xml


@pytest.mark.ros
@pytest.mark.colcon
def test_colcon_without_the_plugin_hears_crosstalk(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    """The control: the same packages, the plugin off, share domain 0 and fail."""
    clear_results(token_workspace)
    summary = colcon_test(token_workspace, ros_env, "--pytest-args", *OFF)
    assert "Summary: 3 tests, 0 errors, 3 failures, 0 skipped" in summary, summary
    found = records(tmp_path)
    assert all(record["domain_id"] is None and record["foreign"] for record in found.values())


def xdist_env(root: Path, ros_env: dict[str, str]) -> dict[str, str]:
    package = root / "src" / "python_tokens"
    return {**ros_env, "PYTHONPATH": f"{package}{os.pathsep}{ros_env.get('PYTHONPATH', '')}"}


@pytest.mark.ros
def test_xdist_gives_each_worker_its_own_id(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    package = token_workspace / "src" / "python_tokens"
    junit = tmp_path / "xdist.xml"
    done = run_pytest(
        package, xdist_env(token_workspace, ros_env), "-n", "3", "test", f"--junit-xml={junit}"
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ros-isolated-test: each xdist worker reserves a ROS_DOMAIN_ID" in done.stdout
    found = records(tmp_path)
    assert sorted(found) == ["amber", "birch", "cobalt"]
    ids = {str(record["domain_id"]) for record in found.values()}
    assert len(ids) == 3 and "None" not in ids, found
    xml = junit.read_text()
    for domain_id in ids:  # the controller's file names every worker's ID
        assert f'value="{domain_id}"' in xml


@pytest.mark.ros
def test_xdist_without_the_plugin_hears_crosstalk(
    token_workspace: Path, ros_env: dict[str, str], tmp_path: Path
) -> None:
    package = token_workspace / "src" / "python_tokens"
    done = run_pytest(package, xdist_env(token_workspace, ros_env), "-n", "3", "test", *OFF)
    assert done.returncode == 1, done.stdout + done.stderr
    found = records(tmp_path)
    assert sorted(found) == ["amber", "birch", "cobalt"]
    assert all(record["domain_id"] is None and record["foreign"] for record in found.values())
