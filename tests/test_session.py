"""Orchestration promises: DISABLE_ROS_ISOLATION wherever the test's environment gets it,
and an --output-file that lost output (a full disk) failing a test that otherwise passed.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import CLI, ament, run_cli
from helpers.results import load_result
from helpers.tiny_disk import fill, run_on_tiny_disk

WARNING = "WARNING: DISABLE_ROS_ISOLATION is set"
#: Writes the domain the test saw, so a test can tell it ran and where.
SEEN = ("sh", "-c", 'echo "${ROS_DOMAIN_ID-unset}" > seen')


# --- A.6: DISABLE_ROS_ISOLATION through --env (ament_add_test's ENV) ------------------------


@pytest.mark.parametrize(
    ("how", "runs"),
    [
        ("--env", True),  # ament_add_test(... ENV DISABLE_ROS_ISOLATION=1)
        ("environment", True),  # the runner's own environment
        ("neither", False),  # control: a preset ID is refused
        ("--env says no", False),  # the assignment has the last word over the environment
    ],
)
def test_disable_ros_isolation_counts_wherever_the_tests_environment_gets_it(
    env: dict[str, str], runner_script: str, tmp_path: Path, how: str, runs: bool
) -> None:
    options = ["--env", "ROS_DOMAIN_ID=42"]
    if how == "--env":
        options += ["--env", "DISABLE_ROS_ISOLATION=1"]
    elif how == "environment":
        env["DISABLE_ROS_ISOLATION"] = "1"
    elif how == "--env says no":
        env["DISABLE_ROS_ISOLATION"] = "1"
        options += ["--env", "DISABLE_ROS_ISOLATION=0"]
    result = tmp_path / "pkg" / "t.xml"
    options.append("--generate-result-on-success")
    proc = ament(runner_script, result, SEEN, env, *options, cwd=tmp_path)
    summary = load_result(result)
    if not runs:
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert not (tmp_path / "seen").exists()
        assert "DISABLE_ROS_ISOLATION=1" in proc.stderr
        assert summary.only.outcome in ("error", "failure")
        return
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "seen").read_text().strip() == "42"
    assert WARNING in proc.stdout  # loudly, as the environment variable does
    if how == "--env":
        assert "(by --env" in proc.stdout
    assert summary.properties.get("isolation") == "disabled"
    assert summary.only.outcome == "passed"


# --- A.8: a full disk under --output-file ---------------------------------------------------


@capabilities.MOUNT_NAMESPACE
@pytest.mark.parametrize(("exit_code", "expected"), [(0, 1), (5, 5)])
def test_an_output_file_that_lost_output_fails_a_passing_test_and_says_so(
    env: dict[str, str], tmp_path: Path, exit_code: int, expected: int
) -> None:
    disk = tmp_path / "disk"
    result = tmp_path / "r.xml"
    # The test fills the disk, then prints more than the output file's last page holds.
    script = (
        f"{fill(disk)}; head -c 20000 /dev/zero | tr '\\0' x; echo; "
        f"echo after-the-disk-filled; exit {exit_code}"
    )
    argv = [
        CLI,
        "run",
        "--junit-xml",
        str(result),
        "--output-file",
        str(disk / "out.log"),
        "--",
        "sh",
        "-c",
        script,
    ]
    done = run_on_tiny_disk(disk, argv, env)
    said = done.stdout.decode(errors="replace")
    assert done.returncode == expected, said + done.stderr.decode(errors="replace")
    assert "after-the-disk-filled" in said  # the console lost nothing
    summary = load_result(result)
    assert "failed" in summary.properties["output_file_error"]
    failed = [case for case in summary.cases if case.outcome in ("error", "failure")]
    assert failed, summary.cases
    text = " ".join(case.message + case.text for case in failed)
    if exit_code == 0:
        assert "output file" in text
    root_text = result.read_text()
    assert "after-the-disk-filled" in root_text  # the output tail is in the result


def test_an_output_file_with_room_passes(env: dict[str, str], tmp_path: Path) -> None:
    """Control: the same run with a disk that has room passes, with no such property."""
    result = tmp_path / "r.xml"
    out = tmp_path / "out.log"
    proc = run_cli(
        [
            "run",
            "--junit-xml",
            str(result),
            "--output-file",
            str(out),
            "--",
            "sh",
            "-c",
            "echo after",
        ],
        env,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = load_result(result)
    assert "output_file_error" not in summary.properties
    assert summary.only.outcome == "passed"
    assert "after" in out.read_text()
