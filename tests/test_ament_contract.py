"""The RUNNER script called exactly as ctest calls it, one test per item of the contract.

The contract is docs/ament-runner-contract.md: what ctest passes to a RUNNER, what
run_test.py does with each argument, the result file and exit code we keep, and where we
differ on purpose. Every test runs real processes against its own lock dir. The core of
the contract (a pass, a failure, the result file, the exit code, the domain) runs on each
supported distro through the ``tools`` fixture: on Jazzy as ever, on Kilted with
.venv-kilted's interpreter and its installed runner.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import ament, run_runner
from helpers.distros import Tools
from helpers.results import DOMAIN_LINE, NO_RESULT, domain_of, load_result, own_result
from lxml import etree


def sh(script: str, *args: str) -> list[str]:
    return ["sh", "-c", script, "sh", *args]


# --- 1. stale result file, folder ----------------------------------------------------------


def test_missing_result_folder_is_created(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "build" / "pkg" / "test_results" / "pkg" / "t.xml"
    proc = tools.ament(
        distro_runner_script,
        result,
        ["true"],
        distro_env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert load_result(result).only.outcome == "passed"


def test_stale_result_file_from_an_earlier_run_does_not_count(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """colcon never clears results: a passing file from last time must not pass this run."""
    result = tmp_path / "pkg" / "t.xml"
    result.parent.mkdir()
    own_result(result, [("stale_case_from_last_run", "passed", "")])
    proc = ament(runner_script, result, ["true"], env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = load_result(result)
    assert summary.only.outcome == "error"
    assert NO_RESULT in summary.only.message
    assert "stale_case_from_last_run" not in result.read_text()


def test_stale_result_file_is_gone_when_the_test_starts(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    result.parent.mkdir()
    own_result(result, [("stale_case_from_last_run", "passed", "")])
    proc = ament(
        runner_script,
        result,
        sh('cp "$1" seen.xml', str(result)),
        env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "stale_case_from_last_run" not in (tmp_path / "seen.xml").read_text()


# --- 2. --skip-test -------------------------------------------------------------------------


def test_skip_test_writes_skipped_result_and_runs_nothing(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, ["touch", "ran"], env, "--skip-test", cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert load_result(result).only.outcome == "skipped"
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout


# --- 3. placeholder before the command ------------------------------------------------------


def test_placeholder_error_result_is_written_before_the_command_starts(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    snapshot = tmp_path / "snapshot.xml"
    proc = ament(
        runner_script,
        result,
        sh('cp "$1" "$2"', str(result), str(snapshot)),
        env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    placeholder = load_result(snapshot).only
    assert placeholder.outcome == "error"
    assert NO_RESULT in placeholder.message
    assert load_result(result).only.outcome == "passed"


def test_placeholder_is_what_remains_when_the_runner_is_killed(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """A ctest timeout kills the runner: the result must still say the test did not finish."""
    result = tmp_path / "pkg" / "t.xml"
    child = "import os, time; print('ready', os.getpid(), flush=True); time.sleep(60)"
    args = [str(result), "--package-name", "pkg", "--command", sys.executable, "-c", child]
    runner = subprocess.Popen(
        [sys.executable, "-u", runner_script, *args],
        env=env,
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert runner.stdout is not None
    test_pid = None
    try:
        for line in runner.stdout:
            if line.startswith("ready "):
                test_pid = int(line.split()[1])
                break
        assert test_pid is not None, "the test never started"
        runner.kill()
        runner.wait(timeout=30)
    finally:
        if test_pid is not None:
            os.kill(test_pid, signal.SIGKILL)
        runner.kill()
        runner.wait()
        runner.stdout.close()
    case = load_result(result).only
    assert case.outcome == "error"
    assert NO_RESULT in case.message


# --- 4. --env / --append-env ----------------------------------------------------------------


def test_env_sets_variables_and_prints_them(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        sh('echo "seen A=$A B=$B"'),
        env,
        "--generate-result-on-success",
        "--env",
        "A=1",
        "B=two words",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen A=1 B=two words\n" in proc.stdout
    assert "A=1" in proc.stdout.split("seen")[0]
    assert "B=two words" in proc.stdout.split("seen")[0]


@pytest.mark.parametrize("before", [None, ""], ids=["unset", "empty"])
def test_append_env_to_unset_variable_gives_plain_value(
    runner_script: str, env: dict[str, str], tmp_path: Path, before: str | None
) -> None:
    """Upstream gives ':/opt/x', and an empty PATH entry means the current directory."""
    env.pop("RIT_PATHLIKE", None)
    if before is not None:
        env["RIT_PATHLIKE"] = before
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        sh('echo "seen [$RIT_PATHLIKE]"'),
        env,
        "--generate-result-on-success",
        "--append-env",
        "RIT_PATHLIKE=/opt/x",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen [/opt/x]\n" in proc.stdout
    assert "RIT_PATHLIKE+=/opt/x" in proc.stdout


def test_append_env_to_set_variable_joins_with_colon(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    env["RIT_PATHLIKE"] = "/a:/b"
    env["LD_LIBRARY_PATH"] = "/lib/one"
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        sh('echo "seen [$RIT_PATHLIKE] [$LD_LIBRARY_PATH]"'),
        env,
        "--generate-result-on-success",
        "--append-env",
        "RIT_PATHLIKE=/x",
        "RIT_PATHLIKE=/y",
        "LD_LIBRARY_PATH=/lib/two",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen [/a:/b:/x:/y] [/lib/one:/lib/two]\n" in proc.stdout


def test_env_then_append_env_on_the_same_variable(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        sh('echo "seen [$RIT_V]"'),
        env,
        "--generate-result-on-success",
        "--env",
        "RIT_V=/set",
        "--append-env",
        "RIT_V=/appended",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen [/set:/appended]\n" in proc.stdout


@pytest.mark.parametrize(
    ("option", "values", "expected"),
    [
        ("--env", ["RIT_V=x", "y"], "x;y"),
        ("--env", ["RIT_V=a", "b", "c", "RIT_W=w"], "a;b;c"),
        ("--append-env", ["RIT_V=/p", "/q"], "/p;/q"),
    ],
    ids=["env", "env-three-parts", "append-env"],
)
def test_value_split_by_cmake_at_semicolons_is_joined_again(
    runner_script: str,
    env: dict[str, str],
    tmp_path: Path,
    option: str,
    values: list[str],
    expected: str,
) -> None:
    env.pop("RIT_V", None)
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        sh('echo "seen [$RIT_V]"'),
        env,
        "--generate-result-on-success",
        option,
        *values,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"seen [{expected}]\n" in proc.stdout


@pytest.mark.parametrize("option", ["--env", "--append-env"])
def test_value_without_equals_and_no_variable_before_is_usage_error(
    runner_script: str, env: dict[str, str], tmp_path: Path, option: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, ["touch", "ran"], env, option, "novalue", cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "novalue" in proc.stderr
    case = load_result(result).only
    assert case.outcome in ("error", "failure")
    assert "novalue" in case.message


@pytest.mark.parametrize(
    "args",
    [
        ["RESULT", "--package-name", "pkg"],
        ["RESULT", "--package-name", "pkg", "--no-such-option", "--command", "touch", "ran"],
        ["RESULT", "--skip-return-code", "x", "--command", "touch", "ran"],
    ],
    ids=["no-command", "unknown-option", "bad-skip-return-code"],
)
def test_other_usage_errors_still_leave_a_result_file(
    runner_script: str, env: dict[str, str], tmp_path: Path, args: list[str]
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    argv = [str(result) if arg == "RESULT" else arg for arg in args]
    proc = run_runner(runner_script, argv, env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert proc.stderr.strip(), "a usage error must say what is wrong"
    assert load_result(result).only.outcome in ("error", "failure")


def test_unusable_output_file_still_leaves_a_result_file(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("")
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        ["touch", "ran"],
        env,
        "--output-file",
        str(blocker / "t.log"),
        cwd=tmp_path,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "not-a-dir" in proc.stderr
    case = load_result(result).only
    assert case.outcome in ("error", "failure")
    assert "not-a-dir" in case.message


# --- 5. running the command ------------------------------------------------------------------


def test_output_file_is_written_as_output_is_produced(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """The test waits (bounded) to see its own output in the file before it ends.

    It looks for the whole line (``grep -x``): the runner's "invoking" line quotes the
    command, ``to-stderr`` included, and is in the file before the test starts.
    """
    result = tmp_path / "pkg" / "t.xml"
    log = tmp_path / "logs" / "t.log"
    proc = ament(
        runner_script,
        result,
        sh(
            "echo first-line; echo to-stderr >&2; i=0;"
            ' while [ $i -lt 200 ] && ! grep -qx to-stderr "$1"; do sleep 0.05; i=$((i+1)); done;'
            ' cp "$1" seen.log; echo last-line',
            str(log),
        ),
        env,
        "--generate-result-on-success",
        "--output-file",
        str(log),
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    seen = (tmp_path / "seen.log").read_text()
    assert "\nfirst-line\nto-stderr\n" in seen
    assert "\nlast-line\n" not in seen
    written = log.read_text()
    assert "first-line\nto-stderr\nlast-line\n" in written


def test_stdout_and_stderr_are_merged_in_order(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        sh("echo one; echo two >&2; echo three; exit 1"),
        env,
        cwd=tmp_path,
    )
    assert proc.returncode == 1
    assert "one\ntwo\nthree\n" in proc.stdout
    assert "two" not in proc.stderr
    assert "one\ntwo\nthree\n" in load_result(result).only.text


def test_command_runs_in_the_working_directory_ctest_chose(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    workdir = tmp_path / "work"
    workdir.mkdir()
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, ["pwd"], env, "--generate-result-on-success", cwd=workdir)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"\n{workdir}\n" in proc.stdout


@pytest.mark.parametrize("kind", ["missing", "not-executable"])
def test_command_that_cannot_be_started_counts_as_code_1(
    runner_script: str, env: dict[str, str], tmp_path: Path, kind: str
) -> None:
    program = tmp_path / "prog"
    if kind == "not-executable":
        program.write_text("#!/bin/sh\necho hi\n")
        program.chmod(0o644)
        expected = "Permission denied"
    else:
        expected = "No such file or directory"
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, [str(program), "arg"], env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    case = load_result(result).only
    assert case.outcome in ("error", "failure")
    assert expected in case.message
    assert str(program) in case.message


def test_undecodable_output_in_the_runner_console_is_passed_through(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    args = [str(result), "--package-name", "pkg", "--command", "printf", r"a\377b\n"]
    proc = subprocess.run(
        [sys.executable, "-u", runner_script, *args],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 1
    assert b"a\xffb\n" in proc.stdout
    # Shown as \xff, not U+FFFD: xunit-viewer aborts on a file holding U+FFFD.
    assert "a\\xffb" in load_result(result).only.message


# --- 6. after the command ---------------------------------------------------------------------


def test_zero_with_generate_result_on_success_writes_passed_result(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = tools.ament(
        distro_runner_script,
        result,
        ["true"],
        distro_env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert summary.only.name == "t"


def test_nonzero_without_result_file_writes_failure_with_the_output(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = tools.ament(
        distro_runner_script,
        result,
        sh("echo line-one-of-output; echo line-two >&2; exit 5"),
        distro_env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 5
    case = load_result(result).only
    assert case.outcome in ("failure", "error")
    assert NO_RESULT in case.message
    assert "line-one-of-output\nline-two\n" in case.text
    assert "line-one-of-output" in case.message


def test_skip_return_code_matching_writes_skipped_result(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script, result, sh("exit 77"), env, "--skip-return-code", "77", cwd=tmp_path
    )
    # ctest's SKIP_RETURN_CODE property needs the code itself to report the test skipped.
    assert proc.returncode == 77
    assert load_result(result).only.outcome == "skipped"


def test_skip_return_code_not_matching_is_a_failure(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, sh("exit 3"), env, "--skip-return-code", "77", cwd=tmp_path)
    assert proc.returncode == 3
    assert load_result(result).only.outcome in ("failure", "error")


def test_zero_without_result_file_and_without_generate_flag_fails(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, sh("echo all-fine"), env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    case = load_result(result).only
    assert case.outcome == "error"
    assert NO_RESULT in case.message
    assert "all-fine" in case.text


def test_zero_when_the_test_deleted_the_result_file_fails(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, ["rm", str(result)], env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert load_result(result).only.outcome == "error"


@pytest.mark.parametrize("exit_code", [0, 4])
def test_own_result_file_with_failures_fails(
    tools: Tools,
    distro_runner_script: str,
    distro_env: dict[str, str],
    tmp_path: Path,
    exit_code: int,
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    written = own_result(
        tmp_path / "own.xml", [("good", "passed", ""), ("bad", "failure", "assert 1 == 2")]
    )
    proc = tools.ament(
        distro_runner_script,
        result,
        sh(f'cp own.xml "$1"; exit {exit_code}', str(result)),
        distro_env,
        cwd=tmp_path,
    )
    assert proc.returncode == (exit_code or 1), proc.stdout + proc.stderr
    original = result.with_name(result.name + ".orig")
    assert original.read_bytes() == written, "the test's own result must be kept beside"
    outcomes = [case.outcome for case in load_result(result).cases]
    # A failing test exiting 4 needs no extra case: the failure already says it failed.
    assert outcomes == ["passed", "failure"]


def test_zero_with_generate_flag_wins_over_the_tests_own_file(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """Contract item 6 checks "code 0 and --generate-result-on-success" first, as upstream."""
    result = tmp_path / "pkg" / "t.xml"
    own_result(tmp_path / "own.xml", [("bad", "failure", "assert 1 == 2")])
    proc = ament(
        runner_script,
        result,
        sh('cp own.xml "$1"', str(result)),
        env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert load_result(result).only.outcome == "passed"


def test_own_result_file_whose_root_counts_errors_fails(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    (tmp_path / "own.xml").write_text(
        '<testsuites errors="1"><testsuite name="s" tests="1">'
        '<testcase classname="C" name="crashed"/></testsuite></testsuites>'
    )
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, sh('cp own.xml "$1"', str(result)), env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr


def test_own_clean_result_file_passes_and_is_kept(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    written = own_result(tmp_path / "own.xml", [("a", "passed", ""), ("b", "skipped", "later")])
    proc = ament(runner_script, result, sh('cp own.xml "$1"', str(result)), env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert result.with_name(result.name + ".orig").read_bytes() == written
    assert [case.name for case in load_result(result).cases] == ["a", "b"]


def test_own_unparsable_result_file_fails(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    (tmp_path / "own.xml").write_text('<testsuites><testsuite name="s" tests="1"><testcase')
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, sh('cp own.xml "$1"', str(result)), env, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "cut off or broken at line 1" in proc.stdout
    cases = load_result(result).cases
    # The case the file was cut inside is kept (as an error), then what was wrong.
    assert [(case.name, case.outcome) for case in cases] == [
        ("unnamed test case 1", "error"),
        ("result file", "error"),
    ]
    assert "Invalid result file t.xml" in cases[-1].message


@pytest.mark.parametrize("failing", [False, True], ids=["clean", "with-failure"])
@pytest.mark.parametrize(
    "payload",
    [
        "\x1b[31mred\x1b[0m bell\x07 raw\x1b end",
        # No colour codes to strip: escaping alone makes the text longer than the file.
        "red bell\x07 end",
    ],
    ids=["ansi-and-control", "control-only"],
)
def test_own_result_file_with_illegal_control_characters_is_tidied_and_parsed(
    runner_script: str, env: dict[str, str], tmp_path: Path, failing: bool, payload: str
) -> None:
    outcome = '<failure message="no">boom</failure>' if failing else ""
    raw = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<testsuites><testsuite name="s" tests="1" failures="{int(failing)}" errors="0" '
        'skipped="0"><testcase classname="C" name="colourful">'
        f"{outcome}<system-out>{payload}</system-out>"
        "</testcase></testsuite></testsuites>\n"
    ).encode()
    with pytest.raises(etree.XMLSyntaxError):
        etree.fromstring(raw)
    (tmp_path / "own.xml").write_bytes(raw)
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, sh('cp own.xml "$1"', str(result)), env, cwd=tmp_path)
    assert proc.returncode == (1 if failing else 0), proc.stdout + proc.stderr
    summary = load_result(result)
    assert summary.only.name == "colourful"
    assert summary.only.outcome == ("failure" if failing else "passed")
    out = etree.parse(str(result)).findtext(".//system-out")
    assert out is not None
    assert out.startswith("red")
    assert out.endswith(" end")
    assert "\x1b" not in out
    assert "\x07" not in out


def test_gtest_result_classnames_are_prefixed_with_the_package_once(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    (tmp_path / "own.xml").write_text(
        '<testsuites tests="2" failures="0" errors="0"><testsuite name="Suite" tests="2" '
        'failures="0" errors="0" skipped="0">'
        '<testcase classname="Suite" name="plain"/>'
        '<testcase classname="pkg.Already" name="prefixed"/>'
        "</testsuite></testsuites>"
    )
    result = tmp_path / "pkg" / "t.gtest.xml"
    proc = ament(runner_script, result, sh('cp own.xml "$1"', str(result)), env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    classnames = [case.classname for case in load_result(result).cases]
    assert classnames == ["pkg.Suite", "pkg.Already"]


def test_every_producers_classnames_get_the_package_prefix_once(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """Upstream prefixes only .gtest.xml; the canonical result prefixes every classname."""
    result = tmp_path / "pkg" / "t.xunit.xml"
    own_result(tmp_path / "own.xml", [("plain", "passed", "")], classname="Suite")
    proc = ament(runner_script, result, sh('cp own.xml "$1"', str(result)), env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [case.classname for case in load_result(result).cases] == ["pkg.Suite"]


# --- --command and help ---------------------------------------------------------------------


def test_options_after_command_belong_to_the_command(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        ["sh", "-c", 'echo "seen $0 --env $*"', "--help", "--skip-test", "-h", "--command"],
        env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen --help --env --skip-test -h --command\n" in proc.stdout
    assert load_result(result).only.outcome == "passed"


@pytest.mark.parametrize("flag", ["-h", "--help"])
def test_help_is_printed_and_nothing_runs(
    runner_script: str, env: dict[str, str], tmp_path: Path, flag: str
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, ["touch", "ran"], env, flag, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "usage:" in proc.stdout
    for option in ("--package-name", "--env", "--append-env", "--skip-return-code", "--command"):
        assert option in proc.stdout
    assert "DISABLE_ROS_ISOLATION" in proc.stdout
    assert not (tmp_path / "ran").exists()
    assert not result.exists()


# --- run_test_isolated.py: the domain -------------------------------------------------------


def test_domain_line_comes_first_and_the_command_sees_that_domain(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    proc = tools.ament(
        distro_runner_script,
        result,
        sh('echo "seen=$ROS_DOMAIN_ID ppid=$PPID"; ros-isolated-test status --json > status.json'),
        distro_env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    first = proc.stdout.splitlines()[0]
    assert DOMAIN_LINE.fullmatch(first), first
    domain = domain_of(first)
    match = re.search(r"^seen=(\d+) ppid=(\d+)$", proc.stdout, re.MULTILINE)
    assert match, proc.stdout
    assert int(match.group(1)) == domain
    # Other rows may name the ID too (a process elsewhere on this machine with it in its
    # environment is listed as a squatter): the runner's lock row is the one to find.
    rows = json.loads((tmp_path / "status.json").read_text())
    locks = [row for row in rows if row["domain_id"] == domain and row["via"] == "lock"]
    assert len(locks) == 1, f"the runner must hold the ID through its lock: {rows}"
    assert locks[0]["pid"] == int(match.group(2)), "held by the runner itself"
    assert load_result(result).properties["ros_domain_id"] == str(domain)


def test_the_test_imports_rclpy_from_the_distros_venv(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path
) -> None:
    """The tier is the distro it says: its test loads that venv's rclpy and sees its ROS_DISTRO.

    Jazzy's environment is the suite's own, which need not name a distro.
    """
    probe = "import os, rclpy; print('rclpy', rclpy.__file__, os.environ.get('ROS_DISTRO'))"
    result = tmp_path / "pkg" / "t.xml"
    command = [tools.python, "-c", probe]
    proc = tools.ament(
        distro_runner_script, result, command, distro_env, "--generate-result-on-success",
        cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    match = re.search(r"^rclpy (\S+) (\S+)$", proc.stdout, re.MULTILINE)
    assert match, proc.stdout
    assert tools.distro.owns(match.group(1)), f"rclpy from outside {tools.distro}: {match[1]}"
    if tools.distro.name != "jazzy":
        assert match.group(2) == tools.distro.name, proc.stdout
    assert load_result(result).only.outcome == "passed"


def test_domain_is_free_again_after_the_run(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    ament(runner_script, result, ["true"], env, "--generate-result-on-success", cwd=tmp_path)
    status = subprocess.run(
        ["ros-isolated-test", "status", "--json"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    assert [row for row in json.loads(status.stdout) if row["via"] == "lock"] == []


def test_disable_ros_isolation_runs_without_reservation_and_warns(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    env["DISABLE_ROS_ISOLATION"] = "1"
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(
        runner_script,
        result,
        sh('echo "seen=${ROS_DOMAIN_ID-unset}"; ros-isolated-test status --json > status.json'),
        env,
        "--generate-result-on-success",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    assert "seen=unset\n" in proc.stdout
    warnings = [line for line in proc.stdout.splitlines() if "WARNING" in line]
    assert len(warnings) == 1, proc.stdout
    assert "DISABLE_ROS_ISOLATION" in warnings[0]
    assert "without isolation" in warnings[0].lower()
    held = json.loads((tmp_path / "status.json").read_text())
    assert [row for row in held if row["via"] == "lock"] == []
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert summary.properties.get("isolation") == "disabled"


def test_no_free_domain_id_fails_without_running(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """Upstream raises RuntimeError; we exit 3 with an error result that says what to do."""
    domain = 231
    env["ROS_ISOLATED_TEST_DOMAINS"] = str(domain)
    env["ROS_ISOLATED_TEST_WAIT_TIMEOUT"] = "0"  # waiting has tests of its own
    port = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        with contextlib.suppress(OSError):  # already taken by someone else: just as good
            port.bind(("", 32768 + domain))
        result = tmp_path / "pkg" / "t.xml"
        proc = ament(runner_script, result, ["touch", "ran"], env, cwd=tmp_path)
    finally:
        port.close()
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "ROS_ISOLATED_TEST_DOMAINS" in proc.stderr
    case = load_result(result).only
    assert case.outcome == "error"
    assert "no free ROS_DOMAIN_ID: all 1 IDs of the pool are in use" in case.message


def test_invalid_domain_pool_is_a_usage_error(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    env["ROS_ISOLATED_TEST_DOMAINS"] = "0-5"
    result = tmp_path / "pkg" / "t.xml"
    proc = ament(runner_script, result, ["touch", "ran"], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "ROS_ISOLATED_TEST_DOMAINS" in proc.stderr
    assert load_result(result).only.outcome == "error"
