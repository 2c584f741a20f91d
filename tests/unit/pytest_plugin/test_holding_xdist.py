"""``holding`` under pytest-xdist: each worker reserves, the controller decides once.

The controller runs no test and holds nothing: it says once what each worker will hold,
or refuses (an explicit --ros-isolation with a preset ROS_DOMAIN_ID), or says the session
is NOT isolated; a worker that gets no ID ends the run with the plugin's exit code 75,
never a crash that xdist restarts (each restart waiting the whole timeout again). The
control: the ID free, the same run passes. Real pytest -n processes; the crosstalk of
real rclpy workers is tests/e2e/test_pytest_plugin_crosstalk.py's, the release on a
signal test_interrupts.py's.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from helpers.commands import HUNG
from helpers.pytest_sessions import (
    NO_ID_EXIT,
    header_lines,
    hold_the_one_id,
    project,
    recorded,
    run_pytest,
)


@pytest.mark.parametrize("explicit", [False, True])
def test_xdist_controller_decides_on_a_preset_id(
    tmp_path: Path, plain_env: dict[str, str], explicit: bool
) -> None:
    """Said once by the controller: refused (explicit) or NOT isolated; never a crash loop."""
    root = project(tmp_path / "pkg")
    args = ("--ros-isolation",) if explicit else ()
    done = run_pytest(root, {**plain_env, "ROS_DOMAIN_ID": "5"}, "-n", "2", *args, "test")
    output = done.stdout + done.stderr
    assert "each xdist worker reserves" not in output
    assert "crashed" not in output
    if explicit:
        assert done.returncode == pytest.ExitCode.USAGE_ERROR, output
        assert "refusing to run: ROS_DOMAIN_ID is already set to '5'" in done.stderr
        assert not (tmp_path / "record.json").exists()
    else:
        assert done.returncode == 0, output
        (line,) = header_lines(done.stdout)
        assert "ROS_DOMAIN_ID is already set to '5'" in line and "NOT isolated" in line
        assert recorded(tmp_path)["ROS_DOMAIN_ID"] == "5"


def test_xdist_with_disable_ros_isolation_says_so(
    tmp_path: Path, plain_env: dict[str, str]
) -> None:
    root = project(tmp_path / "pkg")
    env = {**plain_env, "DISABLE_ROS_ISOLATION": "1"}
    done = run_pytest(root, env, "-n", "2", "test")
    assert done.returncode == 0, done.stdout + done.stderr
    (line,) = header_lines(done.stdout)
    assert "WARNING: DISABLE_ROS_ISOLATION is set: running WITHOUT isolation" in line
    assert recorded(tmp_path)["ROS_DOMAIN_ID"] is None


def test_xdist_pool_exhausted_exits_75_without_restarting_workers(
    tmp_path: Path, exhausted_env: dict[str, str], started: list[subprocess.Popen[bytes]]
) -> None:
    root = project(tmp_path / "pkg")
    holder = hold_the_one_id(tmp_path, exhausted_env, started)
    done = run_pytest(root, exhausted_env, "-n", "2", "test")
    output = done.stdout + done.stderr
    assert done.returncode == NO_ID_EXIT, output
    assert "ros-isolated-test: error: after waiting 1 s, no free ROS_DOMAIN_ID" in done.stderr
    assert "crashed" not in output and "restarting" not in output, output
    assert not (tmp_path / "record.json").exists()
    holder.terminate()
    holder.wait(HUNG)
    # The control: the ID free, it passes.
    again = run_pytest(root, exhausted_env, "-n", "1", "test")
    assert again.returncode == 0, again.stdout + again.stderr
