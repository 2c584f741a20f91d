"""The RUNNER script called exactly as ctest calls it, one test per item of the contract.

The contract is docs/ament-runner-contract.md: what ctest passes to a RUNNER, what
run_test.py does with each argument, the result file and exit code we keep, and where we
differ on purpose. Every test runs real processes against its own lock dir. The core of
the contract (a pass, a failure, the result file, the exit code, the domain) runs on each
supported distro through the ``distro_ctest`` fixture: on Jazzy as ever, on Kilted with
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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers.commands import ament, run_runner
from helpers.distros import Tools
from helpers.results import (
    DOMAIN_LINE,
    NO_RESULT,
    CaseResult,
    ResultSummary,
    domain_of,
    load_result,
    own_result,
)
from lxml import etree


def sh(script: str, *args: str) -> list[str]:
    return ["sh", "-c", script, "sh", *args]


@dataclass(frozen=True)
class Ctest:
    """One test's RUNNER, called as ctest calls it, and the result file it must leave.

    Every test of the contract is the same run-then-assert: ``run`` starts the RUNNER with
    ``RESULT --package-name pkg OPTIONS --command CMD`` in the test's folder and checks the
    exit code (with the output as the message), so each test states only what it sends
    and what it expects.
    """

    script: str
    #: The test's own environment: a test may change it before ``run``.
    env: dict[str, str]
    folder: Path
    #: The distro whose interpreter runs the RUNNER; None: the suite's.
    tools: Tools | None = None

    @property
    def result(self) -> Path:
        """Where ctest tells the RUNNER to write the result: ``pkg/t.xml`` in the folder."""
        return self.folder / "pkg" / "t.xml"

    def run(
        self,
        command: Sequence[str],
        *options: str,
        code: int | None = 0,
        cwd: Path | None = None,
        result: Path | None = None,
    ) -> subprocess.CompletedProcess[str]:
        """The RUNNER on ``command``; its exit code must be ``code`` (None: not checked)."""
        proc = ament(
            self.script,
            self.result if result is None else result,
            command,
            self.env,
            *options,
            cwd=self.folder if cwd is None else cwd,
            tools=self.tools,
        )
        if code is not None:
            assert proc.returncode == code, proc.stdout + proc.stderr
        return proc

    def summary(self) -> ResultSummary:
        return load_result(self.result)

    def case(self) -> CaseResult:
        """The result's one case."""
        return self.summary().only


@pytest.fixture
def ctest(runner_script: str, env: dict[str, str], tmp_path: Path) -> Ctest:
    """The RUNNER on the suite's own interpreter."""
    return Ctest(runner_script, env, tmp_path)


@pytest.fixture
def distro_ctest(
    tools: Tools, distro_runner_script: str, distro_env: dict[str, str], tmp_path: Path
) -> Ctest:
    """The RUNNER as each supported distro's venv has it, on that venv's interpreter."""
    return Ctest(distro_runner_script, distro_env, tmp_path, tools)


# --- 1. stale result file, folder ----------------------------------------------------------


def test_missing_result_folder_is_created(distro_ctest: Ctest, tmp_path: Path) -> None:
    result = tmp_path / "build" / "pkg" / "test_results" / "pkg" / "t.xml"
    distro_ctest.run(["true"], "--generate-result-on-success", result=result)
    assert load_result(result).only.outcome == "passed"


def test_stale_result_file_from_an_earlier_run_does_not_count(ctest: Ctest) -> None:
    """colcon never clears results: a passing file from last time must not pass this run."""
    ctest.result.parent.mkdir()
    own_result(ctest.result, [("stale_case_from_last_run", "passed", "")])
    ctest.run(["true"], code=1)
    case = ctest.case()
    assert case.outcome == "error"
    assert NO_RESULT in case.message
    assert "stale_case_from_last_run" not in ctest.result.read_text()


def test_stale_result_file_is_gone_when_the_test_starts(ctest: Ctest, tmp_path: Path) -> None:
    ctest.result.parent.mkdir()
    own_result(ctest.result, [("stale_case_from_last_run", "passed", "")])
    # The test looks at the result path itself (an argument naming it would be pointed beside).
    look = sh(f'cp "$1/{ctest.result.name}" seen.xml', str(ctest.result.parent))
    ctest.run(look, "--generate-result-on-success")
    assert "stale_case_from_last_run" not in (tmp_path / "seen.xml").read_text()


# --- 2. --skip-test -------------------------------------------------------------------------


def test_skip_test_writes_skipped_result_and_runs_nothing(ctest: Ctest, tmp_path: Path) -> None:
    proc = ctest.run(["touch", "ran"], "--skip-test")
    assert not (tmp_path / "ran").exists()
    assert ctest.case().outcome == "skipped"
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout


# --- 3. placeholder before the command ------------------------------------------------------


def test_placeholder_error_result_is_written_before_the_command_starts(
    ctest: Ctest, tmp_path: Path
) -> None:
    snapshot = tmp_path / "snapshot.xml"
    look = sh(f'cp "$1/{ctest.result.name}" "$2"', str(ctest.result.parent), str(snapshot))
    ctest.run(look, "--generate-result-on-success")
    placeholder = load_result(snapshot).only
    assert placeholder.outcome == "error"
    assert NO_RESULT in placeholder.message
    assert ctest.case().outcome == "passed"


def test_placeholder_is_what_remains_when_the_runner_is_killed(ctest: Ctest) -> None:
    """A ctest timeout kills the runner: the result must still say the test did not finish."""
    child = "import os, time; print('ready', os.getpid(), flush=True); time.sleep(60)"
    args = [str(ctest.result), "--package-name", "pkg", "--command", sys.executable, "-c", child]
    runner = subprocess.Popen(
        [sys.executable, "-u", ctest.script, *args],
        env=ctest.env,
        cwd=ctest.folder,
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
    case = ctest.case()
    assert case.outcome == "error"
    assert NO_RESULT in case.message


# --- 4. --env / --append-env ----------------------------------------------------------------


def test_env_sets_variables_and_prints_them(ctest: Ctest) -> None:
    proc = ctest.run(
        sh('echo "seen A=$A B=$B"'),
        "--generate-result-on-success",
        "--env",
        "A=1",
        "B=two words",
    )
    assert "seen A=1 B=two words\n" in proc.stdout
    assert "A=1" in proc.stdout.split("seen")[0]
    assert "B=two words" in proc.stdout.split("seen")[0]


@pytest.mark.parametrize("before", [None, ""], ids=["unset", "empty"])
def test_append_env_to_unset_variable_gives_plain_value(ctest: Ctest, before: str | None) -> None:
    """Upstream gives ':/opt/x', and an empty PATH entry means the current directory."""
    ctest.env.pop("RIT_PATHLIKE", None)
    if before is not None:
        ctest.env["RIT_PATHLIKE"] = before
    proc = ctest.run(
        sh('echo "seen [$RIT_PATHLIKE]"'),
        "--generate-result-on-success",
        "--append-env",
        "RIT_PATHLIKE=/opt/x",
    )
    assert "seen [/opt/x]\n" in proc.stdout
    assert "RIT_PATHLIKE+=/opt/x" in proc.stdout


def test_append_env_to_set_variable_joins_with_colon(ctest: Ctest) -> None:
    ctest.env["RIT_PATHLIKE"] = "/a:/b"
    ctest.env["LD_LIBRARY_PATH"] = "/lib/one"
    proc = ctest.run(
        sh('echo "seen [$RIT_PATHLIKE] [$LD_LIBRARY_PATH]"'),
        "--generate-result-on-success",
        "--append-env",
        "RIT_PATHLIKE=/x",
        "RIT_PATHLIKE=/y",
        "LD_LIBRARY_PATH=/lib/two",
    )
    assert "seen [/a:/b:/x:/y] [/lib/one:/lib/two]\n" in proc.stdout


def test_env_then_append_env_on_the_same_variable(ctest: Ctest) -> None:
    proc = ctest.run(
        sh('echo "seen [$RIT_V]"'),
        "--generate-result-on-success",
        "--env",
        "RIT_V=/set",
        "--append-env",
        "RIT_V=/appended",
    )
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
    ctest: Ctest, option: str, values: list[str], expected: str
) -> None:
    ctest.env.pop("RIT_V", None)
    proc = ctest.run(sh('echo "seen [$RIT_V]"'), "--generate-result-on-success", option, *values)
    assert f"seen [{expected}]\n" in proc.stdout


@pytest.mark.parametrize("option", ["--env", "--append-env"])
def test_value_without_equals_and_no_variable_before_is_usage_error(
    ctest: Ctest, tmp_path: Path, option: str
) -> None:
    proc = ctest.run(["touch", "ran"], option, "novalue", code=2)
    assert not (tmp_path / "ran").exists()
    assert "novalue" in proc.stderr
    case = ctest.case()
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
    ctest: Ctest, tmp_path: Path, args: list[str]
) -> None:
    argv = [str(ctest.result) if arg == "RESULT" else arg for arg in args]
    proc = run_runner(ctest.script, argv, ctest.env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert proc.stderr.strip(), "a usage error must say what is wrong"
    assert ctest.case().outcome in ("error", "failure")


def test_unusable_output_file_still_leaves_a_result_file(ctest: Ctest, tmp_path: Path) -> None:
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("")
    proc = ctest.run(["touch", "ran"], "--output-file", str(blocker / "t.log"), code=2)
    assert not (tmp_path / "ran").exists()
    assert "not-a-dir" in proc.stderr
    case = ctest.case()
    assert case.outcome in ("error", "failure")
    assert "not-a-dir" in case.message


# --- 5. running the command ------------------------------------------------------------------


def test_output_file_is_written_as_output_is_produced(ctest: Ctest, tmp_path: Path) -> None:
    """The test waits (bounded) to see its own output in the file before it ends.

    It looks for the whole line (``grep -x``): the runner's "invoking" line quotes the
    command, ``to-stderr`` included, and is in the file before the test starts.
    """
    log = tmp_path / "logs" / "t.log"
    ctest.run(
        sh(
            "echo first-line; echo to-stderr >&2; i=0;"
            ' while [ $i -lt 200 ] && ! grep -qx to-stderr "$1"; do sleep 0.05; i=$((i+1)); done;'
            ' cp "$1" seen.log; echo last-line',
            str(log),
        ),
        "--generate-result-on-success",
        "--output-file",
        str(log),
    )
    seen = (tmp_path / "seen.log").read_text()
    assert "\nfirst-line\nto-stderr\n" in seen
    assert "\nlast-line\n" not in seen
    written = log.read_text()
    assert "first-line\nto-stderr\nlast-line\n" in written


def test_stdout_and_stderr_are_merged_in_order(ctest: Ctest) -> None:
    proc = ctest.run(sh("echo one; echo two >&2; echo three; exit 1"), code=1)
    assert "one\ntwo\nthree\n" in proc.stdout
    assert "two" not in proc.stderr
    assert "one\ntwo\nthree\n" in ctest.case().text


def test_command_runs_in_the_working_directory_ctest_chose(ctest: Ctest, tmp_path: Path) -> None:
    workdir = tmp_path / "work"
    workdir.mkdir()
    proc = ctest.run(["pwd"], "--generate-result-on-success", cwd=workdir)
    assert f"\n{workdir}\n" in proc.stdout


@pytest.mark.parametrize("kind", ["missing", "not-executable"])
def test_command_that_cannot_be_started_counts_as_code_1(
    ctest: Ctest, tmp_path: Path, kind: str
) -> None:
    program = tmp_path / "prog"
    if kind == "not-executable":
        program.write_text("#!/bin/sh\necho hi\n")
        program.chmod(0o644)
        expected = "Permission denied"
    else:
        expected = "No such file or directory"
    ctest.run([str(program), "arg"], code=1)
    case = ctest.case()
    assert case.outcome in ("error", "failure")
    assert expected in case.message
    assert str(program) in case.message


def test_undecodable_output_in_the_runner_console_is_passed_through(ctest: Ctest) -> None:
    args = [str(ctest.result), "--package-name", "pkg", "--command", "printf", r"a\377b\n"]
    proc = subprocess.run(
        [sys.executable, "-u", ctest.script, *args],
        env=ctest.env,
        cwd=ctest.folder,
        capture_output=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 1
    assert b"a\xffb\n" in proc.stdout
    # Shown as \xff, not U+FFFD: xunit-viewer aborts on a file holding U+FFFD.
    assert "a\\xffb" in ctest.case().message


# --- 6. after the command ---------------------------------------------------------------------


def test_zero_with_generate_result_on_success_writes_passed_result(distro_ctest: Ctest) -> None:
    distro_ctest.run(["true"], "--generate-result-on-success")
    case = distro_ctest.case()
    assert case.outcome == "passed"
    assert case.name == "t"


def test_nonzero_without_result_file_writes_failure_with_the_output(distro_ctest: Ctest) -> None:
    distro_ctest.run(
        sh("echo line-one-of-output; echo line-two >&2; exit 5"),
        "--generate-result-on-success",
        code=5,
    )
    case = distro_ctest.case()
    assert case.outcome in ("failure", "error")
    assert NO_RESULT in case.message
    assert "line-one-of-output\nline-two\n" in case.text
    assert "line-one-of-output" in case.message


def test_skip_return_code_matching_writes_skipped_result(ctest: Ctest) -> None:
    # ctest's SKIP_RETURN_CODE property needs the code itself to report the test skipped.
    ctest.run(sh("exit 77"), "--skip-return-code", "77", code=77)
    assert ctest.case().outcome == "skipped"


def test_skip_return_code_not_matching_is_a_failure(ctest: Ctest) -> None:
    ctest.run(sh("exit 3"), "--skip-return-code", "77", code=3)
    assert ctest.case().outcome in ("failure", "error")


def test_zero_without_result_file_and_without_generate_flag_fails(ctest: Ctest) -> None:
    ctest.run(sh("echo all-fine"), code=1)
    case = ctest.case()
    assert case.outcome == "error"
    assert NO_RESULT in case.message
    assert "all-fine" in case.text


def test_zero_when_the_test_deleted_the_result_file_fails(ctest: Ctest) -> None:
    ctest.run(sh(f'rm "$1/{ctest.result.name}"', str(ctest.result.parent)), code=1)
    assert ctest.case().outcome == "error"


@pytest.mark.parametrize("exit_code", [0, 4])
def test_own_result_file_with_failures_fails(
    distro_ctest: Ctest, tmp_path: Path, exit_code: int
) -> None:
    result = distro_ctest.result
    written = own_result(
        tmp_path / "own.xml", [("good", "passed", ""), ("bad", "failure", "assert 1 == 2")]
    )
    distro_ctest.run(sh(f'cp own.xml "$1"; exit {exit_code}', str(result)), code=exit_code or 1)
    original = result.with_name(result.name + ".orig")
    assert original.read_bytes() == written, "the test's own result must be kept beside"
    outcomes = [case.outcome for case in distro_ctest.summary().cases]
    # A failing test exiting 4 needs no extra case: the failure already says it failed.
    assert outcomes == ["passed", "failure"]


def test_zero_with_generate_flag_wins_over_the_tests_own_file(ctest: Ctest, tmp_path: Path) -> None:
    """Contract item 6 checks "code 0 and --generate-result-on-success" first, as upstream."""
    own_result(tmp_path / "own.xml", [("bad", "failure", "assert 1 == 2")])
    ctest.run(sh('cp own.xml "$1"', str(ctest.result)), "--generate-result-on-success")
    assert ctest.case().outcome == "passed"


def copy_own(ctest: Ctest) -> list[str]:
    """The test command that hands in ``own.xml`` as the test's own result file."""
    return sh('cp own.xml "$1"', str(ctest.result))


def test_own_result_file_whose_root_counts_errors_fails(ctest: Ctest, tmp_path: Path) -> None:
    (tmp_path / "own.xml").write_text(
        '<testsuites errors="1"><testsuite name="s" tests="1">'
        '<testcase classname="C" name="crashed"/></testsuite></testsuites>'
    )
    ctest.run(copy_own(ctest), code=1)


def test_own_clean_result_file_passes_and_is_kept(ctest: Ctest, tmp_path: Path) -> None:
    written = own_result(tmp_path / "own.xml", [("a", "passed", ""), ("b", "skipped", "later")])
    ctest.run(copy_own(ctest))
    assert ctest.result.with_name(ctest.result.name + ".orig").read_bytes() == written
    assert [case.name for case in ctest.summary().cases] == ["a", "b"]


def test_own_unparsable_result_file_fails(ctest: Ctest, tmp_path: Path) -> None:
    (tmp_path / "own.xml").write_text('<testsuites><testsuite name="s" tests="1"><testcase')
    proc = ctest.run(copy_own(ctest), code=1)
    assert "cut off or broken at line 1" in proc.stdout
    cases = ctest.summary().cases
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
    ctest: Ctest, tmp_path: Path, failing: bool, payload: str
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
    ctest.run(copy_own(ctest), code=1 if failing else 0)
    case = ctest.case()
    assert case.name == "colourful"
    assert case.outcome == ("failure" if failing else "passed")
    out = etree.parse(str(ctest.result)).findtext(".//system-out")
    assert out is not None
    assert out.startswith("red")
    assert out.endswith(" end")
    assert "\x1b" not in out
    assert "\x07" not in out


def test_gtest_result_classnames_are_prefixed_with_the_package_once(
    ctest: Ctest, tmp_path: Path
) -> None:
    (tmp_path / "own.xml").write_text(
        '<testsuites tests="2" failures="0" errors="0"><testsuite name="Suite" tests="2" '
        'failures="0" errors="0" skipped="0">'
        '<testcase classname="Suite" name="plain"/>'
        '<testcase classname="pkg.Already" name="prefixed"/>'
        "</testsuite></testsuites>"
    )
    result = tmp_path / "pkg" / "t.gtest.xml"
    ctest.run(sh('cp own.xml "$1"', str(result)), result=result)
    classnames = [case.classname for case in load_result(result).cases]
    assert classnames == ["pkg.Suite", "pkg.Already"]


def test_every_producers_classnames_get_the_package_prefix_once(
    ctest: Ctest, tmp_path: Path
) -> None:
    """Upstream prefixes only .gtest.xml; the canonical result prefixes every classname."""
    result = tmp_path / "pkg" / "t.xunit.xml"
    own_result(tmp_path / "own.xml", [("plain", "passed", "")], classname="Suite")
    ctest.run(sh('cp own.xml "$1"', str(result)), result=result)
    assert [case.classname for case in load_result(result).cases] == ["pkg.Suite"]


# --- --command and help ---------------------------------------------------------------------


def test_options_after_command_belong_to_the_command(ctest: Ctest) -> None:
    proc = ctest.run(
        ["sh", "-c", 'echo "seen $0 --env $*"', "--help", "--skip-test", "-h", "--command"],
        "--generate-result-on-success",
    )
    assert "seen --help --env --skip-test -h --command\n" in proc.stdout
    assert ctest.case().outcome == "passed"


@pytest.mark.parametrize("flag", ["-h", "--help"])
def test_help_is_printed_and_nothing_runs(ctest: Ctest, tmp_path: Path, flag: str) -> None:
    proc = ctest.run(["touch", "ran"], flag)
    assert "usage:" in proc.stdout
    for option in ("--package-name", "--env", "--append-env", "--skip-return-code", "--command"):
        assert option in proc.stdout
    assert "DISABLE_ROS_ISOLATION" in proc.stdout
    assert not (tmp_path / "ran").exists()
    assert not ctest.result.exists()


# --- run_test_isolated.py: the domain -------------------------------------------------------


def test_domain_line_comes_first_and_the_command_sees_that_domain(
    distro_ctest: Ctest, tmp_path: Path
) -> None:
    proc = distro_ctest.run(
        sh('echo "seen=$ROS_DOMAIN_ID ppid=$PPID"; ros-isolated-test status --json > status.json'),
        "--generate-result-on-success",
    )
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
    assert distro_ctest.summary().properties["ros_domain_id"] == str(domain)


def test_the_test_imports_rclpy_from_the_distros_venv(tools: Tools, distro_ctest: Ctest) -> None:
    """The tier is the distro it says: its test loads that venv's rclpy and sees its ROS_DISTRO.

    Jazzy's environment is the suite's own, which need not name a distro.
    """
    probe = "import os, rclpy; print('rclpy', rclpy.__file__, os.environ.get('ROS_DISTRO'))"
    proc = distro_ctest.run([tools.python, "-c", probe], "--generate-result-on-success")
    match = re.search(r"^rclpy (\S+) (\S+)$", proc.stdout, re.MULTILINE)
    assert match, proc.stdout
    assert tools.distro.owns(match.group(1)), f"rclpy from outside {tools.distro}: {match[1]}"
    if tools.distro.name != "jazzy":
        assert match.group(2) == tools.distro.name, proc.stdout
    assert distro_ctest.case().outcome == "passed"


def test_domain_is_free_again_after_the_run(ctest: Ctest) -> None:
    ctest.run(["true"], "--generate-result-on-success", code=None)
    status = subprocess.run(
        ["ros-isolated-test", "status", "--json"],
        env=ctest.env,
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    assert [row for row in json.loads(status.stdout) if row["via"] == "lock"] == []


def test_disable_ros_isolation_runs_without_reservation_and_warns(
    ctest: Ctest, tmp_path: Path
) -> None:
    ctest.env["DISABLE_ROS_ISOLATION"] = "1"
    proc = ctest.run(
        sh('echo "seen=${ROS_DOMAIN_ID-unset}"; ros-isolated-test status --json > status.json'),
        "--generate-result-on-success",
    )
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    assert "seen=unset\n" in proc.stdout
    warnings = [line for line in proc.stdout.splitlines() if "WARNING" in line]
    assert len(warnings) == 1, proc.stdout
    assert "DISABLE_ROS_ISOLATION" in warnings[0]
    assert "without isolation" in warnings[0].lower()
    held = json.loads((tmp_path / "status.json").read_text())
    assert [row for row in held if row["via"] == "lock"] == []
    summary = ctest.summary()
    assert summary.only.outcome == "passed"
    assert summary.properties.get("isolation") == "disabled"


def test_no_free_domain_id_fails_without_running(ctest: Ctest, tmp_path: Path) -> None:
    """Upstream raises RuntimeError; we exit 3 with an error result that says what to do."""
    domain = 231
    ctest.env["ROS_ISOLATED_TEST_DOMAINS"] = str(domain)
    ctest.env["ROS_ISOLATED_TEST_WAIT_TIMEOUT"] = "0"  # waiting has tests of its own
    port = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        with contextlib.suppress(OSError):  # already taken by someone else: just as good
            port.bind(("", 32768 + domain))
        proc = ctest.run(["touch", "ran"], code=3)
    finally:
        port.close()
    assert not (tmp_path / "ran").exists()
    assert "ROS_ISOLATED_TEST_DOMAINS" in proc.stderr
    case = ctest.case()
    assert case.outcome == "error"
    assert "no free ROS_DOMAIN_ID: all 1 IDs of the pool are in use" in case.message


def test_invalid_domain_pool_is_a_usage_error(ctest: Ctest, tmp_path: Path) -> None:
    ctest.env["ROS_ISOLATED_TEST_DOMAINS"] = "0-5"
    proc = ctest.run(["touch", "ran"], code=2)
    assert not (tmp_path / "ran").exists()
    assert "ROS_ISOLATED_TEST_DOMAINS" in proc.stderr
    assert ctest.case().outcome == "error"
