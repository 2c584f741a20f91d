"""``holding``: machine resources held with the session's ID until pytest ends.

``--ros-isolated-test-resources`` (or the ini option) is held by the session's own
reservation: another runner asking for the same gets nothing while the session lives and
gets it once pytest ended (the control). A bad request is a usage error naming where it
was given; under xdist each worker holds the request; under a runner of ours the plugin
holds nothing (the runner holds what it was asked). Real pytest and runner processes.
Which option wins, and that a request turns isolation on, is test_options.py's.
"""

from __future__ import annotations

import subprocess
from collections.abc import Mapping
from pathlib import Path

import pytest
from helpers.commands import CLI, HUNG
from helpers.processes import wait_for
from helpers.pytest_sessions import (
    NO_ID_EXIT,
    PYTEST,
    project,
    run_in,
    run_pytest,
    start_pytest,
)

#: Holds its session open until GO exists (so another runner can try the same resources).
HOLDING_TEST = """\
import os, pathlib, time

def test_holds_until_go():
    pathlib.Path(os.environ["READY"]).touch()
    deadline = time.monotonic() + 120
    while not os.path.exists(os.environ["GO"]) and time.monotonic() < deadline:
        time.sleep(0.05)
"""


def _lidar_runner(env: Mapping[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """Another runner asking for the one lidar, giving up after 1 s."""
    return run_in(
        cwd, env, [CLI, "run", "--resources", "lidar=1", "--wait-timeout", "1", "--", "true"]
    )


def test_the_session_holds_its_resources_until_pytest_ends(
    tmp_path: Path, resource_env: dict[str, str], started: list[subprocess.Popen[bytes]]
) -> None:
    """The ini option's request is held by the session: another runner asking for it gets
    nothing while the session lives (exit 3), and gets it once pytest ended (control)."""
    ready, go, junit = tmp_path / "ready", tmp_path / "go", tmp_path / "junit.xml"
    env = {**resource_env, "READY": str(ready), "GO": str(go)}
    root = project(tmp_path / "pkg", HOLDING_TEST)
    (root / "pytest.ini").write_text("[pytest]\nros_isolated_test_resources = lidar=1\n")
    log = tmp_path / "session.log"
    session = start_pytest(root, env, log, started, ("test", f"--junit-xml={junit}"))
    wait_for(ready)
    refused = _lidar_runner(env, tmp_path)
    assert refused.returncode == 3, refused.stdout + refused.stderr
    go.touch()
    assert session.wait(HUNG) == 0, log.read_text()
    assert "ros-isolated-test: holding lidar=1 of lidar=1" in log.read_text()
    assert '<property name="resources" value="lidar=1"' in junit.read_text()
    after = _lidar_runner(env, tmp_path)
    assert after.returncode == 0, after.stdout + after.stderr


@pytest.mark.parametrize(
    ("args", "ini", "says"),
    [
        (("--ros-isolated-test-resources", "lidar"), "", "--ros-isolated-test-resources: 'lidar'"),
        ((), "lidar", "ini option ros_isolated_test_resources: 'lidar'"),
        ((), "lidar=2", "ini option ros_isolated_test_resources: lidar=2 is more than"),
        # The option is read, not the ini's (good) value.
        (
            ("--ros-isolated-test-resources", "lidar=0"),
            "lidar=1",
            "--ros-isolated-test-resources: lidar='0' is zero",
        ),
    ],
)
def test_a_bad_request_is_a_usage_error_naming_the_option(
    tmp_path: Path, resource_env: dict[str, str], args: tuple[str, ...], ini: str, says: str
) -> None:
    root = project(tmp_path / "pkg")
    (root / "pytest.ini").write_text(f"[pytest]\nros_isolated_test_resources = {ini}\n")
    done = run_pytest(root, resource_env, *args, "test")
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, done.stdout + done.stderr
    assert f"ros-isolated-test: {says}" in done.stderr, done.stderr
    assert not (tmp_path / "record.json").exists()


@pytest.mark.parametrize("capacity", ["lidar=2", "lidar=1"])
def test_xdist_holds_the_resources_per_worker(
    tmp_path: Path, resource_env: dict[str, str], capacity: str
) -> None:
    """Two workers, lidar=1 each: they fit a capacity of 2; with 1, the second worker waits
    for the first, which holds it until pytest ends: no lidar in time, exit 75."""
    root = project(tmp_path / "pkg")
    env = {
        **resource_env,
        "ROS_ISOLATED_TEST_CAPACITY": capacity,
        "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "2",
    }
    done = run_pytest(root, env, "-n", "2", "--ros-isolated-test-resources", "lidar=1", "test")
    output = done.stdout + done.stderr
    assert "ros-isolated-test: each xdist worker reserves a ROS_DOMAIN_ID and lidar=1" in output
    if capacity == "lidar=2":
        assert done.returncode == 0, output
    else:
        assert done.returncode == NO_ID_EXIT, output
        assert "crashed" not in output and "restarting" not in output, output


def test_under_the_runner_the_plugin_holds_no_resources(
    tmp_path: Path, resource_env: dict[str, str], one_id: dict[str, str]
) -> None:
    """The runner holds what it was asked; the plugin asking again could wait for itself."""
    root = project(tmp_path / "pkg")
    env = {**resource_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0"}
    argv = [CLI, "run", "--resources", "lidar=1", "--", *PYTEST]
    done = run_in(root, env, [*argv, "--ros-isolated-test-resources", "lidar=1", "test"])
    assert done.returncode == 0, done.stdout + done.stderr
    assert (
        "ros-isolated-test: --ros-isolated-test-resources (lidar=1) not held by the plugin"
        in done.stdout
    ), done.stdout
