"""``not_run``: every error that stops a test before it runs carries what the stop means.

The errors are raised in four layers and answered in one place (``runner.exit_codes``):
a busy machine is the runner's 3 and the plugin's 75, anything to fix the runner's 2 and
the plugin's 4; a refusal records a failure, anything else an error. Real runs show the
same through the command: a preset ID (a refusal), a bad pool (a setting), no free ID
(busy), each with its result file; the control is a run that goes through.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.commands import run_cli, the_error_line
from helpers.results import load_result

from ros_isolated_test import not_run
from ros_isolated_test.ament.args import UsageError
from ros_isolated_test.domain_coordinator.lock_dir import LockDirError
from ros_isolated_test.domain_coordinator.pool import PoolSpecError
from ros_isolated_test.domain_coordinator.resource_holds import CapacityConflictError
from ros_isolated_test.domain_coordinator.resources import ResourceSpecError
from ros_isolated_test.domain_coordinator.waiting import PoolExhaustedError, ResourcesBusyError
from ros_isolated_test.pytest_plugin import holding
from ros_isolated_test.runner import exit_codes
from ros_isolated_test.runner.discovery import DiscoveryError
from ros_isolated_test.runner.environment import RefusedError
from ros_isolated_test.runner.partition import PartitionSettingError
from ros_isolated_test.runner.settings import SettingsError
from ros_isolated_test.shard.spec import ShardSettingError

BUSY = (PoolExhaustedError, ResourcesBusyError, LockDirError)
TO_FIX = (
    SettingsError,
    DiscoveryError,
    PartitionSettingError,
    RefusedError,
    ShardSettingError,
    PoolSpecError,
    ResourceSpecError,
    CapacityConflictError,
    UsageError,
)


@pytest.mark.parametrize("kind", BUSY + TO_FIX, ids=lambda kind: kind.__name__)
def test_each_error_maps_to_one_runner_code_and_one_plugin_code(kind: type[Exception]) -> None:
    error = kind("why")
    assert isinstance(error, not_run.NotRun)
    busy = kind in BUSY
    assert exit_codes.for_not_run(error) == (exit_codes.NO_DOMAIN if busy else exit_codes.USAGE)
    assert exit_codes.plugin_code(error) == (
        exit_codes.PLUGIN_BUSY if busy else exit_codes.PLUGIN_USAGE
    )
    assert error.outcome == (not_run.FAILURE if kind is RefusedError else not_run.ERROR)


def test_the_plugins_busy_code_is_the_one_exit_codes_names() -> None:
    assert holding.NO_ID_EXIT == exit_codes.PLUGIN_BUSY


@pytest.mark.parametrize(
    ("setting", "code", "outcome"),
    [
        ({"ROS_DOMAIN_ID": "7"}, exit_codes.USAGE, "failure"),
        ({"ROS_ISOLATED_TEST_DOMAINS": "nonsense"}, exit_codes.USAGE, "error"),
        ({"ROS_ISOLATED_TEST_LOCK_DIR": "FILE"}, exit_codes.NO_DOMAIN, "error"),
        ({}, exit_codes.PASSED, "passed"),  # control: nothing stops it
    ],
    ids=["refused", "setting", "lock dir unusable", "control"],
)
def test_a_run_that_never_started_says_why_in_its_code_and_result(
    env: dict[str, str], tmp_path: Path, setting: dict[str, str], code: int, outcome: str
) -> None:
    scoped = {**env, **setting}
    if setting.get("ROS_ISOLATED_TEST_LOCK_DIR") == "FILE":
        (tmp_path / "a-file").write_text("")  # a file where the lock directory should be
        scoped["ROS_ISOLATED_TEST_LOCK_DIR"] = str(tmp_path / "a-file")
    result = tmp_path / "r.xml"
    proc = run_cli(["run", "--junit-xml", str(result), "--", "true"], scoped, cwd=tmp_path)
    assert proc.returncode == code, proc.stdout + proc.stderr
    if code:
        assert the_error_line(proc)
    assert load_result(result).only.outcome == outcome
