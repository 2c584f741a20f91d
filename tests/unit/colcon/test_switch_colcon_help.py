"""``colcon --help`` lists ``ROS_ISOLATED_TEST_COLCON`` (the environment_variable entry point)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ros_isolated_test.colcon.switch import VARIABLE

COLCON = str(Path(sys.executable).parent / "colcon")


def _help(tmp_path: Path, **extra: str) -> str:
    env = {"PATH": str(Path(sys.executable).parent) + ":/usr/bin:/bin", "HOME": str(tmp_path)}
    proc = subprocess.run(
        [COLCON, "--help"],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
        cwd=tmp_path,
        env={**env, **extra},
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


@pytest.mark.colcon
def test_colcon_help_lists_the_switch_and_what_off_does(tmp_path: Path) -> None:
    said = _help(tmp_path)
    assert VARIABLE in said
    described = " ".join(said.split(VARIABLE, 1)[1].split())[:200]
    assert described.startswith("Set to off to turn ros-isolated-test's colcon"), described
    # Control: the entry point blocked, colcon lists no such variable.
    blocked = _help(
        tmp_path, COLCON_EXTENSION_BLOCKLIST="colcon_core.environment_variable.ros_isolated_test"
    )
    assert VARIABLE not in blocked
