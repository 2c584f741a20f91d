"""How the test ended is reconciled with the cases it reported, through RUNNER and ``run``.

A test's own result file can say "all passed" while the process exited 3, died of
SIGSEGV or was stopped by the timeout; the canonical file must not read as a pass then.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from helpers.commands import run_cli, run_runner
from helpers.results import NO_RESULT, ResultSummary, domain_of, load_result, own_result
from lxml import etree

from ros_isolated_test import __version__
from ros_isolated_test.xunit import validate

ENTRIES = ("runner", "run")
EXIT_CASE = "test process exit"


def invoke(
    entry: str,
    runner_script: str,
    result: Path,
    command: list[str],
    env: dict[str, str],
    cwd: Path,
    *options: str,
) -> subprocess.CompletedProcess[str]:
    """The test through the ctest RUNNER, or through ``ros-isolated-test run --junit-xml``."""
    if entry == "runner":
        args = [str(result), "--package-name", "pkg", *options, "--command", *command]
        return run_runner(runner_script, args, env, cwd=cwd)
    args = ["run", "--package-name", "pkg", "--junit-xml", str(result), *options, "--", *command]
    return run_cli(args, env, cwd=cwd)


def checked(path: Path) -> ResultSummary:
    """The canonical file, valid against our schema and with counts that match its cases."""
    root = etree.parse(str(path)).getroot()
    assert validate.problems(root) == []
    return load_result(path)


def assert_run_properties(
    summary: ResultSummary, proc: subprocess.CompletedProcess[str], command_part: str
) -> None:
    props = summary.properties
    assert props["ros_domain_id"] == str(domain_of(proc.stdout))
    assert command_part in props["command"]
    assert float(props["duration"]) >= 0
    assert props["runner_version"] == __version__
    assert "exit_code" in props or "signal" in props, props


@pytest.fixture
def own(tmp_path: Path) -> Path:
    """A clean result file as the test writes it: two passing cases."""
    path = tmp_path / "own.xml"
    own_result(path, [("a", "passed", ""), ("b", "passed", "")])
    return path


# --- a non-zero exit while every case passed ---------------------------------------------------


@pytest.mark.parametrize("entry", ENTRIES)
def test_nonzero_exit_with_every_case_passing_adds_a_failed_case(
    entry: str, runner_script: str, env: dict[str, str], tmp_path: Path, own: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", 'echo said-before; cp "$0" "$1"; exit 3', str(own), str(result)]
    proc = invoke(entry, runner_script, result, command, env, tmp_path)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    summary = checked(result)
    assert [(case.classname, case.name, case.outcome) for case in summary.cases] == [
        ("pkg.C", "a", "passed"),
        ("pkg.C", "b", "passed"),
        ("pkg.t", EXIT_CASE, "failure"),
    ]
    exit_case = summary.cases[-1]
    expected = "The test process exited with code 3, although every test case it reported passed."
    assert exit_case.message == expected
    assert exit_case.text == expected
    assert summary.properties["exit_code"] == "3"
    assert "signal" not in summary.properties
    assert_run_properties(summary, proc, "exit 3")
    assert result.with_name("t.xml.orig").is_file(), "the test's own file is kept beside"


def test_skip_return_code_with_a_clean_file_adds_nothing(
    runner_script: str, env: dict[str, str], tmp_path: Path, own: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", 'cp "$0" "$1"; exit 77', str(own), str(result)]
    proc = invoke(
        "runner", runner_script, result, command, env, tmp_path, "--skip-return-code", "77"
    )
    assert proc.returncode == 77, proc.stdout + proc.stderr
    assert [case.name for case in checked(result).cases] == ["a", "b"]


# --- death by a signal -------------------------------------------------------------------------


@pytest.mark.parametrize("entry", ENTRIES)
def test_death_by_signal_after_writing_a_clean_file_names_the_signal(
    entry: str, runner_script: str, env: dict[str, str], tmp_path: Path, own: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", 'cp "$0" "$1"; ulimit -c 0; kill -SEGV $$', str(own), str(result)]
    proc = invoke(entry, runner_script, result, command, env, tmp_path)
    if entry == "run":
        assert proc.returncode == 139, proc.stdout + proc.stderr
    else:
        assert proc.returncode != 0, proc.stdout + proc.stderr
    summary = checked(result)
    assert [case.name for case in summary.cases] == ["a", "b", EXIT_CASE]
    exit_case = summary.cases[-1]
    assert exit_case.outcome == "failure"
    assert "killed by SIGSEGV (signal 11)" in exit_case.message
    assert "although every test case it reported passed" in exit_case.message
    assert "killed by SIGSEGV (signal 11)" in exit_case.text
    assert summary.properties["signal"] == "SIGSEGV"
    assert_run_properties(summary, proc, "kill -SEGV")


def test_death_by_signal_is_named_even_when_a_case_failed(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    own = tmp_path / "own.xml"
    own_result(own, [("a", "passed", ""), ("b", "failure", "assert 1 == 2")])
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", 'cp "$0" "$1"; ulimit -c 0; kill -SEGV $$', str(own), str(result)]
    proc = invoke("run", runner_script, result, command, env, tmp_path)
    assert proc.returncode == 139, proc.stdout + proc.stderr
    summary = checked(result)
    assert [(case.name, case.outcome) for case in summary.cases] == [
        ("a", "passed"),
        ("b", "failure"),
        (EXIT_CASE, "failure"),
    ]
    assert summary.cases[1].message == "assert 1 == 2"
    assert summary.cases[-1].message == "The test process was killed by SIGSEGV (signal 11)."


# --- timeout -----------------------------------------------------------------------------------


def timed_out_after(message: str) -> float:
    match = re.search(r"timed out after (\d+(?:\.\d+)?) s \(--timeout 1\)", message)
    assert match, message
    return float(match.group(1))


def test_timeout_after_writing_a_clean_file_says_so_and_how_long_it_ran(
    runner_script: str, env: dict[str, str], tmp_path: Path, own: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", 'cp "$0" "$1"; sleep 30', str(own), str(result)]
    proc = invoke("run", runner_script, result, command, env, tmp_path, "--timeout", "1")
    assert proc.returncode == 124, proc.stdout + proc.stderr
    summary = checked(result)
    assert [case.name for case in summary.cases] == ["a", "b", EXIT_CASE]
    exit_case = summary.cases[-1]
    assert exit_case.outcome == "failure"
    assert 0.9 <= timed_out_after(exit_case.message) < 10
    assert "although every test case it reported passed" in exit_case.message
    assert 0.9 <= float(summary.properties["duration"]) < 10
    assert_run_properties(summary, proc, "sleep 30")


def test_timeout_without_a_result_file_says_so_with_the_output(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", "echo waiting-forever; sleep 30"]
    proc = invoke("run", runner_script, result, command, env, tmp_path, "--timeout", "1")
    assert proc.returncode == 124, proc.stdout + proc.stderr
    case = checked(result).only
    assert case.outcome == "failure"
    assert 0.9 <= timed_out_after(case.message) < 10
    assert "waiting-forever" in case.message
    assert "waiting-forever" in case.text


# --- no result file ----------------------------------------------------------------------------


@pytest.mark.parametrize("entry", ENTRIES)
def test_no_result_file_and_nonzero_exit_keeps_the_contract(
    entry: str, runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", "echo tail-one; echo tail-two >&2; exit 6"]
    proc = invoke(entry, runner_script, result, command, env, tmp_path)
    assert proc.returncode == 6, proc.stdout + proc.stderr
    summary = checked(result)
    case = summary.only
    assert case.outcome in ("failure", "error")
    assert (case.classname, case.name) == ("pkg.t", "t")
    assert "exited with code 6" in case.message
    assert "tail-one\ntail-two\n" in case.message
    assert "tail-one\ntail-two\n" in case.text
    if entry == "runner":
        assert NO_RESULT in case.message
    assert summary.properties["exit_code"] == "6"
    assert_run_properties(summary, proc, "exit 6")


# --- an exit of 0 does not hide the test's own failures ----------------------------------------


def test_run_keeps_the_failures_of_the_tests_own_file_when_it_exits_0(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    """`run` has no --generate-result-on-success to ask for upstream's overwrite."""
    own = tmp_path / "own.xml"
    own_result(own, [("a", "passed", ""), ("b", "failure", "assert 1 == 2")])
    result = tmp_path / "pkg" / "t.xml"
    command = ["sh", "-c", 'cp "$0" "$1"', str(own), str(result)]
    proc = invoke("run", runner_script, result, command, env, tmp_path)
    summary = checked(result)
    assert [(case.name, case.outcome) for case in summary.cases] == [
        ("a", "passed"),
        ("b", "failure"),
    ], proc.stdout + proc.stderr
    assert result.with_name("t.xml.orig").is_file(), "the test's own file is kept beside"
