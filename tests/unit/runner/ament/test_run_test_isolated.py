"""``runner/ament/run_test_isolated.py``: the RUNNER's old path still runs a test, isolated.

A workspace configured before the script moved to ``ros_isolated_test/ament/`` keeps the
old path in its CMake cache (ament_add_test's RUNNER). Run as ctest runs it, the old path
must do exactly what the new one does: the test gets a reserved ID, its result file is
written, a usage error still leaves a result file. The control: the same test through the
script's own path.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from helpers.commands import REPO, ament, run_runner, the_error_line
from helpers.results import load_result

OLD = REPO / "ros_isolated_test" / "runner" / "ament" / "run_test_isolated.py"
NEW = REPO / "ros_isolated_test" / "ament" / "run_test_isolated.py"
#: The test: says the ID it was given, and fails without one.
SAYS_ITS_ID = (sys.executable, "-c", "import os; print('ID', os.environ['ROS_DOMAIN_ID'])")


@pytest.mark.parametrize("script", [OLD, NEW], ids=["old path", "control: new path"])
def test_the_old_path_runs_the_test_on_a_reserved_id(
    env: dict[str, str], tmp_path: Path, script: Path
) -> None:
    result = tmp_path / "t.xml"
    proc = ament(
        str(script), result, SAYS_ITS_ID, env, "--generate-result-on-success", cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    held = [line.split()[1] for line in proc.stdout.splitlines() if line.startswith("ID ")]
    assert len(held) == 1 and held[0].isdigit(), proc.stdout
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert summary.properties["ros_domain_id"] == held[0]


def test_a_usage_error_through_the_old_path_still_leaves_a_result_file(
    env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "t.xml"
    proc = run_runner(str(OLD), [str(result), "--no-such-option"], env, cwd=tmp_path)
    assert proc.returncode == 2
    assert "--no-such-option" in the_error_line(proc)
    assert load_result(result).only.outcome == "error"
