"""Runs that show the Gazebo partition a test got: through ``run`` or the RUNNER, and its file.

Shared by the partition's own tests (the name a real run gets) and the environment
policy's (a preset partition refused, the switch, DISABLE_ROS_ISOLATION).
"""

from __future__ import annotations

import subprocess
from collections.abc import Sequence
from pathlib import Path

from helpers.commands import through

#: What the test prints: the partition variables it got, and its runner's PID.
SHOW = 'echo "gz=${GZ_PARTITION-unset} ign=${IGN_PARTITION-unset} runner=$PPID"'


def invoke(
    mode: str,
    runner_script: str,
    env: dict[str, str],
    cwd: Path,
    command: Sequence[str],
    options: Sequence[str] = (),
) -> tuple[subprocess.CompletedProcess[str], Path]:
    """``command`` through ``run --junit-xml`` or the RUNNER (with ``options``); and its file."""
    result = cwd / "out" / "pkg" / "t.xml"
    return through(mode, runner_script, env, cwd, command, result, options), result
