"""``cli``: the command group: which copy answers (``--version``), and ``--help`` that
names every command, variable and exit code.
"""

from __future__ import annotations

import platform
from pathlib import Path

import pytest
from helpers.commands import CLI, run_cli

import ros_isolated_test


def test_version_names_the_install_and_its_python(env: dict[str, str]) -> None:
    """Which copy answers: the version, the package folder it runs from, the interpreter."""
    proc = run_cli(["--version"], env)
    assert proc.returncode == 0, proc.stderr
    package = Path(ros_isolated_test.__file__).resolve().parent
    interpreter = Path(CLI).read_text().splitlines()[0].removeprefix("#!")
    assert proc.stdout.splitlines() == [
        f"ros-isolated-test {ros_isolated_test.__version__}",
        f"installed in {package}",
        f"Python {platform.python_version()} ({interpreter})",
    ]


def test_run_help_names_every_variable_and_exit_code(env: dict[str, str]) -> None:
    proc = run_cli(["run", "--help"], env)
    assert proc.returncode == 0, proc.stderr
    text = " ".join(proc.stdout.split())
    for word in (
        "--wait-timeout",
        "--discovery-range",
        "ROS_ISOLATED_TEST_WAIT_TIMEOUT",
        "ROS_ISOLATED_TEST_DISCOVERY_RANGE",
        "DISABLE_ROS_ISOLATION",
        "--output-file could not be fully written",
        "the --junit-xml or --output-file path cannot be used",
        "--resources",
        "ROS_ISOLATED_TEST_RESOURCES",
        "ROS_ISOLATED_TEST_CAPACITY",
        "124",
        "126/127",
    ):
        assert word in text, word
    top = run_cli(["--help"], env)
    for name in ("ROS_ISOLATED_TEST_DOMAINS", "ROS_ISOLATED_TEST_LOCK_DIR"):
        assert name in top.stdout


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ["--help"],
            [
                "run",
                "runner-path",
                "status",
                "ROS_ISOLATED_TEST_DOMAINS",
                "ROS_ISOLATED_TEST_LOCK_DIR",
                "DISABLE_ROS_ISOLATION",
            ],
        ),
        (
            ["run", "--help"],
            [
                "--",
                "--junit-xml",
                "--timeout",
                "--output-file",
                "Exit codes",
                "128+N",
                "124",
                "126/127",
                "ROS_DOMAIN_ID",
                "DISABLE_ROS_ISOLATION=1",
            ],
        ),
        (["runner-path", "--help"], ["RUNNER", "ament_add_test", "add_launch_test"]),
        (["status", "--help"], ["--json", "32768"]),
    ],
    ids=["top", "run", "runner-path", "status"],
)
def test_help_of_every_command(
    env: dict[str, str], tmp_path: Path, args: list[str], expected: list[str]
) -> None:
    proc = run_cli(args, env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Usage:" in proc.stdout
    for text in expected:
        assert text in proc.stdout, f"{text!r} missing from `{' '.join(args)}`"
