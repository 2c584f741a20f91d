"""A preset ROS_DOMAIN_ID is refused, in the shell ``run`` and in the ctest RUNNER alike.

Upstream silently runs on a preset ID; we refuse, because an exported ID turns a parallel
run into crosstalk nobody notices. DISABLE_ROS_ISOLATION=1 is the documented way out.
The refusal runs on each supported distro (the ``tools`` fixture); it matters most on
Kilted, whose upstream runner silently replaces a preset ID instead.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.commands import (
    ERROR_PREFIX,
    MODES,
    the_error_line,
    through,
)
from helpers.distros import Tools
from helpers.results import load_result


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("value", ["5", ""], ids=["set", "empty"])
def test_preset_domain_id_is_refused_and_nothing_runs(
    tools: Tools,
    distro_runner_script: str,
    distro_env: dict[str, str],
    tmp_path: Path,
    mode: str,
    value: str,
) -> None:
    env = distro_env
    env["ROS_DOMAIN_ID"] = value
    proc = through(mode, distro_runner_script, env, tmp_path, ["touch", "ran"], tools=tools)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists(), "a refused test must not run"
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    line = the_error_line(proc)
    assert f"ROS_DOMAIN_ID is already set to {value!r}" in line
    assert "share that domain" in line, "the message must say why"
    assert "unset ROS_DOMAIN_ID" in line, "the message must name the way out"
    assert "DISABLE_ROS_ISOLATION=1" in line
    if not value:
        assert "domain 0" in line


@pytest.mark.parametrize("mode", MODES)
def test_refusal_is_recorded_in_the_result_file_as_a_failed_case(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    env = distro_env
    env["ROS_DOMAIN_ID"] = "17"
    result = tmp_path / "out" / "pkg" / "t.xml"
    proc = through(
        mode, distro_runner_script, env, tmp_path, ["touch", "ran"], result=result, tools=tools
    )
    assert proc.returncode == 2
    assert not (tmp_path / "ran").exists()
    message = the_error_line(proc).removeprefix(ERROR_PREFIX)
    case = load_result(result).only
    assert case.outcome == "failure"
    assert case.message == message
    assert "ROS_DOMAIN_ID is already set to '17'" in case.text


@pytest.mark.parametrize("option", ["--env", "--append-env"])
def test_domain_id_passed_with_env_option_is_refused(
    runner_script: str, env: dict[str, str], tmp_path: Path, option: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = through(
        "runner",
        runner_script,
        env,
        tmp_path,
        ["touch", "ran"],
        result=result,
        runner_options=[option, "ROS_DOMAIN_ID=7"],
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    line = the_error_line(proc)
    assert "ROS_DOMAIN_ID='7'" in line
    assert "--env" in line
    assert "DISABLE_ROS_ISOLATION=1" in line
    case = load_result(result).only
    assert case.outcome == "failure"
    assert case.message == line.removeprefix(ERROR_PREFIX)


@pytest.mark.parametrize("mode", MODES)
def test_disable_ros_isolation_runs_with_the_preset_id_and_warns(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str
) -> None:
    env["ROS_DOMAIN_ID"] = "42"
    env["DISABLE_ROS_ISOLATION"] = "1"
    result = tmp_path / "pkg" / "t.xml"
    proc = through(
        mode, runner_script, env, tmp_path, ["sh", "-c", 'echo "seen=$ROS_DOMAIN_ID"'], result
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen=42\n" in proc.stdout
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    warnings = [line for line in proc.stdout.splitlines() if "WARNING" in line]
    assert len(warnings) == 1, proc.stdout
    assert "ROS_DOMAIN_ID=42" in warnings[0]
    assert "WITHOUT isolation" in warnings[0]
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert summary.properties["ros_domain_id"] == "42"


def test_disable_ros_isolation_lets_env_option_set_the_id(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    env["DISABLE_ROS_ISOLATION"] = "1"
    proc = through(
        "runner",
        runner_script,
        env,
        tmp_path,
        ["sh", "-c", 'echo "seen=$ROS_DOMAIN_ID"'],
        runner_options=["--env", "ROS_DOMAIN_ID=7"],
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen=7\n" in proc.stdout
    assert any("WARNING" in line and "ROS_DOMAIN_ID=7" in line for line in proc.stdout.splitlines())


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("word", ["0", "false"])
def test_disable_ros_isolation_0_does_not_disable(
    runner_script: str, env: dict[str, str], tmp_path: Path, mode: str, word: str
) -> None:
    env["DISABLE_ROS_ISOLATION"] = word
    env["ROS_DOMAIN_ID"] = "5"
    proc = through(mode, runner_script, env, tmp_path, ["touch", "ran"])
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "ROS_DOMAIN_ID is already set to '5'" in the_error_line(proc)

    del env["ROS_DOMAIN_ID"]
    isolated = through(
        mode, runner_script, env, tmp_path, ["sh", "-c", 'echo "seen=$ROS_DOMAIN_ID"']
    )
    assert isolated.returncode == 0, isolated.stdout + isolated.stderr
    first = isolated.stdout.splitlines()[0]
    assert first.startswith("Running with ROS_DOMAIN_ID ")
    assert f"seen={first.split()[3]}\n" in isolated.stdout
    assert "WARNING" not in isolated.stdout
