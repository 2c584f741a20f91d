"""Edges found in review: each one once ended a run badly (a traceback, a hang, a lost file)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from helpers.commands import CLI, run_cli
from helpers.results import load_result

from ros_isolated_test.xunit.result_file import normalise_file


def test_a_failing_output_file_never_ends_the_run(env: dict[str, str], tmp_path: Path) -> None:
    result = tmp_path / "r.xml"
    proc = run_cli(
        ["run", "--junit-xml", str(result), "--output-file", "/dev/full", "--", "echo", "hi"],
        env,
        cwd=tmp_path,
    )
    # The run goes on, but an incomplete output file fails it and is named in the result.
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "writing output file /dev/full failed" in proc.stdout
    assert "hi" in proc.stdout
    assert "No space left on device" in result.read_text()
    load_result(result)


def test_a_leftover_that_keeps_printing_cannot_hold_the_runner(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Without a limit on draining, the runner waited for as long as the spammer lived."""
    spam = "(while :; do echo spam; sleep 0.05; done) & exit 0"
    try:  # the spammer never stops by itself: a runner that waits for it never ends
        proc = subprocess.run(
            [CLI, "run", "--", "sh", "-c", spam],
            env=env,
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("the runner still waited for the spammer's output after 120 s")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "left running by the test" in proc.stdout


def test_usage_errors_of_run_still_leave_the_junit_file(
    env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "out" / "r.xml"
    env["ROS_ISOLATED_TEST_WAIT_TIMEOUT"] = "soon"
    proc = run_cli(["run", "--junit-xml", str(result), "--", "true"], env, cwd=tmp_path)
    assert proc.returncode == 2
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    case = load_result(result).only
    assert case.outcome == "error"
    assert "ROS_ISOLATED_TEST_WAIT_TIMEOUT" in case.message  # the variable, not the option


def test_counts_too_large_for_an_integer_are_read_not_fatal(tmp_path: Path) -> None:
    source = tmp_path / "t.xml"
    source.write_text(
        '<testsuite name="s" tests="1" failures="inf" errors="1e400">'
        '<testcase classname="C" name="a"/></testsuite>'
    )
    data, failed = normalise_file(source, "pkg", "t")
    assert b'name="a"' in data
    assert not failed
