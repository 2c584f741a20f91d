"""``environment``'s Gazebo partition policy: one per test, a preset one refused like an ID.

Gazebo's transport ignores ROS_DOMAIN_ID, so the policy gives the test GZ_PARTITION and
IGN_PARTITION of this runner's own (``partition``) and refuses a partition someone else
set, as it refuses a preset ROS_DOMAIN_ID (test_environment.py): kept, the test's
simulation would share it with every other test run on it. The switch
(ROS_ISOLATED_TEST_GZ_PARTITION=off) sets none and refuses none; DISABLE_ROS_ISOLATION
leaves the user's partitions as they are. Decided in process first, then through real
runs of ``run`` and the RUNNER, each refusal beside the run it lets through.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest
from helpers.commands import (
    ERROR_PREFIX,
    MODES,
    the_error_line,
)
from helpers.partition_runs import SHOW, invoke
from helpers.results import domain_of, load_result

from ros_isolated_test.runner import environment, partition, settings
from ros_isolated_test.runner.request import EnvAssignment

# --- the policy -------------------------------------------------------------------------


def _decide(
    environ: dict[str, str], assignments: Sequence[EnvAssignment] = ()
) -> environment.Policy:
    return environment.decide(assignments, settings.read(environ), environ)


def test_the_policy_sets_both_variables_to_this_runners_partition() -> None:
    policy = _decide({})
    env = policy.for_domain(11)
    assert env["GZ_PARTITION"] == env["IGN_PARTITION"] == partition.for_this_runner(11)
    assert policy.partition_for(11) == partition.for_this_runner(11)


@pytest.mark.parametrize("variable", partition.VARIABLES)
@pytest.mark.parametrize("value", ["sim", ""])
def test_a_preset_partition_is_refused_naming_it_and_the_fix(variable: str, value: str) -> None:
    with pytest.raises(environment.RefusedError) as refused:
        _decide({variable: value})
    message = str(refused.value)
    assert refused.value.variable == variable
    assert f"{variable} is already set to {value!r}" in message
    assert f"unset {variable}" in message
    assert "ROS_ISOLATED_TEST_GZ_PARTITION=off" in message
    assert "DISABLE_ROS_ISOLATION=1" in message
    assert "\n" not in message


@pytest.mark.parametrize("variable", partition.VARIABLES)
@pytest.mark.parametrize("append", [False, True], ids=["env", "append-env"])
def test_a_partition_passed_with_env_is_refused(variable: str, append: bool) -> None:
    given = [EnvAssignment(variable, "sim", append=append)]
    with pytest.raises(environment.RefusedError) as refused:
        _decide({}, given)
    option = "--append-env" if append else "--env"  # the option to edit, named
    assert f"{variable}='sim' is passed with {option}, so" in str(refused.value)
    assert f"remove it from {option} (" in str(refused.value)


def test_disable_ros_isolation_keeps_the_users_partitions() -> None:
    environ = {"GZ_PARTITION": "mine", "IGN_PARTITION": "old", "DISABLE_ROS_ISOLATION": "1"}
    policy = _decide(environ)
    assert not policy.isolate
    assert (policy.env["GZ_PARTITION"], policy.env["IGN_PARTITION"]) == ("mine", "old")
    given = [EnvAssignment("DISABLE_ROS_ISOLATION", "1"), EnvAssignment("GZ_PARTITION", "x")]
    assert _decide({}, given).env["GZ_PARTITION"] == "x"


def test_the_switch_off_sets_nothing_and_refuses_nothing() -> None:
    off = {partition.OPT_OUT_ENV: "off"}
    policy = _decide(off)
    assert policy.isolate and policy.partition_for(3) is None
    env = policy.for_domain(3)
    assert "GZ_PARTITION" not in env and "IGN_PARTITION" not in env
    kept = _decide({**off, "GZ_PARTITION": "mine"}).for_domain(3)
    assert kept["GZ_PARTITION"] == "mine" and "IGN_PARTITION" not in kept
    # From --env (ament_add_test's ENV), which has the last word over the environment.
    by_env = _decide({}, [EnvAssignment(partition.OPT_OUT_ENV, "off")])
    assert by_env.partition_for(3) is None
    back_on = _decide(off, [EnvAssignment(partition.OPT_OUT_ENV, "on")])
    assert back_on.partition_for(3) == partition.for_this_runner(3)
    with pytest.raises(environment.RefusedError, match=r"\(by --env\)=.*neither on nor off"):
        _decide({}, [EnvAssignment(partition.OPT_OUT_ENV, "maybe")])


# --- real runs: run and the RUNNER -------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("variable", partition.VARIABLES)
def test_a_preset_partition_is_refused_and_nothing_runs(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str, variable: str
) -> None:
    env[variable] = "shared_sim"
    proc, result = invoke(mode, runner_script, env, tmp_path, ["touch", "ran"])
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists(), "a refused test must not run"
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    line = the_error_line(proc).removeprefix(ERROR_PREFIX)
    assert f"{variable} is already set to 'shared_sim'" in line
    assert f"unset {variable}" in line and "DISABLE_ROS_ISOLATION=1" in line
    case = load_result(result).only
    assert case.outcome == "failure"
    assert case.message == line
    # The control: the same run without the preset variable runs.
    del env[variable]
    again, _ = invoke(mode, runner_script, env, tmp_path, ["touch", "ran"])
    assert again.returncode == 0, again.stdout + again.stderr
    assert (tmp_path / "ran").exists()


@pytest.mark.parametrize("variable", partition.VARIABLES)
def test_a_partition_passed_with_env_to_the_runner_is_refused(
    runner_script: str, env: dict[str, str], tmp_path: Path, variable: str
) -> None:
    options = ["--env", f"{variable}=shared_sim"]
    proc, result = invoke("runner", runner_script, env, tmp_path, ["touch", "ran"], options)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    line = the_error_line(proc).removeprefix(ERROR_PREFIX)
    assert f"{variable}='shared_sim' is passed with --env" in line
    assert load_result(result).only.message == line


@pytest.mark.parametrize("mode", MODES)
def test_disable_ros_isolation_runs_on_the_users_partitions(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    env.update(GZ_PARTITION="mine", IGN_PARTITION="mine_too", DISABLE_ROS_ISOLATION="1")
    proc, result = invoke(mode, runner_script, env, tmp_path, ["sh", "-c", SHOW])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "gz=mine ign=mine_too " in proc.stdout
    assert "WITHOUT isolation" in proc.stdout
    assert load_result(result).properties["gz_partition"] == "mine"


def test_disable_ros_isolation_by_env_lets_env_set_a_partition(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    options = ["--env", "DISABLE_ROS_ISOLATION=1", "--env", "GZ_PARTITION=mine"]
    proc, _ = invoke("runner", runner_script, env, tmp_path, ["sh", "-c", SHOW], options)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "gz=mine ign=unset " in proc.stdout


@pytest.mark.parametrize("mode", MODES)
def test_the_switch_off_sets_no_partition_and_keeps_a_preset_one(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    env[partition.OPT_OUT_ENV] = "off"
    proc, result = invoke(mode, runner_script, env, tmp_path, ["sh", "-c", SHOW])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "gz=unset ign=unset " in proc.stdout
    assert "Gazebo transport partition not set (ROS_ISOLATED_TEST_GZ_PARTITION=off)" in (
        proc.stdout
    )
    properties = load_result(result).properties
    assert properties["gz_partition"] == "not set (ROS_ISOLATED_TEST_GZ_PARTITION=off)"
    assert properties["ros_domain_id"] == str(domain_of(proc.stdout))  # still isolated
    env["GZ_PARTITION"] = "mine"
    kept, _ = invoke(mode, runner_script, env, tmp_path, ["sh", "-c", SHOW])
    assert kept.returncode == 0, kept.stdout + kept.stderr
    assert "gz=mine ign=unset " in kept.stdout


def test_the_switch_off_through_env_as_cmake_env_passes_it(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    options = ["--env", f"{partition.OPT_OUT_ENV}=off"]
    proc, _ = invoke("runner", runner_script, env, tmp_path, ["sh", "-c", SHOW], options)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "gz=unset ign=unset " in proc.stdout


@pytest.mark.parametrize("mode", MODES)
def test_a_bad_switch_value_is_a_usage_error_with_a_result_file(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    env[partition.OPT_OUT_ENV] = "sometimes"
    proc, result = invoke(mode, runner_script, env, tmp_path, ["touch", "ran"])
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    line = the_error_line(proc).removeprefix(ERROR_PREFIX)
    assert "ROS_ISOLATED_TEST_GZ_PARTITION='sometimes' is neither on nor off" in line
    assert load_result(result).only.message == line
