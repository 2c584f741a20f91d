"""``verdict``: how the test ended, turned into its result file's final word and the exit code.

The rules are ``exit_codes``' (test_exit_codes.py); here they are applied to real ends
of real commands (``supervisor.run``) on a real result file: a test that wrote no result
fails in the RUNNER's mode unless asked to generate one, a skip code is a skipped case,
a failure carries its exit and output tail, a test's own file is adopted and its
failures fail the run. An --output-file that lost output (a full disk) fails a test
that otherwise passed and says so in a case of its own, while a test that failed keeps
its code; the console never fails a run. Each refusal or failure beside its control.
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import pytest
from helpers import capabilities
from helpers.commands import CLI, run_cli
from helpers.results import NO_RESULT, ResultSummary, load_result
from helpers.tiny_disk import fill, run_on_tiny_disk

from ros_isolated_test.process import supervisor
from ros_isolated_test.process.capture import OutputCapture
from ros_isolated_test.runner import exit_codes, settings
from ros_isolated_test.runner.request import Mode, RunRequest
from ros_isolated_test.runner.verdict import conclude
from ros_isolated_test.xunit.result_file import ResultFile

#: Writes a result file of its own at $1: one case, failing when $2 says so.
OWN_RESULT = (
    'if [ "$2" = fail ]; then inner=\'<failure message="own failure"/>\'; else inner=; fi; '
    'printf \'<testsuite name="s" tests="1"><testcase classname="s" name="c">%s'
    '</testcase></testsuite>\' "$inner" > "$1"'
)


class Concluded:
    """One command run for real, then concluded: the code, the result file, the notes."""

    def __init__(self, code: int, result: Path, console: Path) -> None:
        self.code = code
        self.path = result
        self.console = console.read_text()

    @property
    def summary(self) -> ResultSummary:
        return load_result(self.path)


def _concluded(
    tmp_path: Path,
    command: list[str],
    mode: Mode = Mode.AMENT,
    output: BinaryIO | None = None,
    **options: object,
) -> Concluded:
    """``command`` run by the supervisor, its end concluded as the session would."""
    path = tmp_path / "pkg" / "t.xml"
    request = RunRequest(
        tuple(command),
        mode,
        settings.defaults(),
        result_file=path,
        **options,  # type: ignore[arg-type]
    )
    result = ResultFile(path, request.command, request.package, request.test_name)
    result.prepare()
    assert result.write_placeholder()
    console = tmp_path / "console"
    with console.open("wb", buffering=0) as stream:
        capture = OutputCapture(stream, output)
        outcome = supervisor.run(request.command, {"PATH": "/usr/bin:/bin"}, capture)
        code = conclude(request, result, capture, outcome)
    return Concluded(code, path, console)


# --- what the result file says, and the code ---------------------------------------------


def test_a_passing_test_that_wrote_no_result_fails_unless_one_is_generated(
    tmp_path: Path,
) -> None:
    """run_test.py's contract: exit 0 and no file is no proof the test ran."""
    missing = _concluded(tmp_path / "missing", ["true"])
    assert missing.code == exit_codes.FAILED
    case = missing.summary.only
    assert case.outcome == "error" and NO_RESULT in case.message, case
    assert missing.summary.properties["exit"] == "exited with code 0"
    assert "Failing it (write one, or use --generate-result-on-success)" in missing.console
    # The control: asked to generate one, the same test passes.
    generated = _concluded(tmp_path / "generated", ["true"], generate_result_on_success=True)
    assert generated.code == exit_codes.PASSED
    assert generated.summary.only.outcome == "passed"
    assert generated.summary.properties["exit_code"] == "0"


def test_the_skip_return_code_is_a_skipped_case_and_any_other_code_a_failure(
    tmp_path: Path,
) -> None:
    skipped = _concluded(tmp_path / "skipped", ["sh", "-c", "exit 77"], skip_return_code=77)
    case = skipped.summary.only
    assert (case.outcome, case.message) == ("skipped", "Test skipped: it returned 77."), case
    assert "return code 77 means skipped (--skip-return-code)" in skipped.console
    assert skipped.code == 77  # ctest's SKIP_RETURN_CODE sees the code the test gave
    # The control: another code is the test's failure, with its code.
    failed = _concluded(tmp_path / "failed", ["sh", "-c", "exit 3"], skip_return_code=77)
    assert failed.code == 3 and failed.summary.only.outcome == "failure"


def test_a_failure_without_a_result_of_its_own_carries_its_exit_and_output_tail(
    tmp_path: Path,
) -> None:
    done = _concluded(tmp_path, ["sh", "-c", "echo its last words; exit 3"])
    assert done.code == 3
    case = done.summary.only
    assert case.outcome == "failure"
    said = case.message + case.text
    assert "did not generate a result file. The test exited with code 3." in said, case
    assert "its last words" in case.message + case.text, case
    assert done.summary.properties["exit_code"] == "3"


@pytest.mark.parametrize(("mode", "code"), [(Mode.AMENT, 1), (Mode.SHELL, 127)])
def test_a_command_that_cannot_start_is_an_error_with_its_callers_code(
    tmp_path: Path, mode: Mode, code: int
) -> None:
    """run_test.py counts it as code 1; a shell says 127."""
    done = _concluded(tmp_path, [str(tmp_path / "no-such-test")], mode)
    assert done.code == code
    case = done.summary.only
    assert case.outcome == "error" and "could not be started" in case.message + case.text
    assert "invocation failed:" in done.console


def test_the_tests_own_file_is_adopted_and_its_failures_fail_the_run(tmp_path: Path) -> None:
    path = tmp_path / "failing" / "pkg" / "t.xml"
    failing = _concluded(tmp_path / "failing", ["sh", "-c", OWN_RESULT, "own", str(path), "fail"])
    assert failing.code == exit_codes.FAILED  # it exited 0: its file has the last word
    assert failing.summary.only.message == "own failure"
    assert f"the result file {path} reports failures or errors" in failing.console
    assert path.with_name("t.xml.orig").is_file()  # the test's own file, kept aside
    # The control: a passing file of its own passes, without --generate-result-on-success.
    path = tmp_path / "passing" / "pkg" / "t.xml"
    passing = _concluded(tmp_path / "passing", ["sh", "-c", OWN_RESULT, "own", str(path), "ok"])
    assert passing.code == exit_codes.PASSED
    assert passing.summary.only.outcome == "passed"


# --- an output file that lost output -------------------------------------------------------


@pytest.mark.parametrize(("command", "expected"), [("true", 1), ("exit 5", 5)])
def test_a_lost_output_fails_only_a_pass_with_a_case_naming_the_file(
    tmp_path: Path, command: str, expected: int
) -> None:
    """In process: the capture's own file error, as a full disk leaves it."""
    with open("/dev/full", "wb", buffering=0) as full:
        done = _concluded(
            tmp_path,
            ["sh", "-c", f"echo some output; {command}"],
            output=full,
            generate_result_on_success=True,
            output_file=Path("/dev/full"),
        )
    assert done.code == expected
    summary = done.summary
    assert "No space left on device" in summary.properties["output_file_error"]
    if expected == 1:
        lost = [case for case in summary.cases if case.name == "output file"]
        assert len(lost) == 1 and lost[0].outcome == "error", summary.cases
        assert "so --output-file /dev/full is incomplete" in lost[0].message
    else:
        # The control: a test that failed keeps its own code and its one case.
        assert summary.only.outcome == "failure"


# --- the same, in real runs -----------------------------------------------------------------


@capabilities.MOUNT_NAMESPACE
@pytest.mark.parametrize(("exit_code", "expected"), [(0, 1), (5, 5)])
def test_an_output_file_that_lost_output_fails_a_passing_test_and_says_so(
    env: dict[str, str], tmp_path: Path, exit_code: int, expected: int
) -> None:
    disk = tmp_path / "disk"
    result = tmp_path / "r.xml"
    # The test fills the disk, then prints more than the output file's last page holds.
    script = (
        f"{fill(disk)}; head -c 20000 /dev/zero | tr '\\0' x; echo; "
        f"echo after-the-disk-filled; exit {exit_code}"
    )
    argv = [
        CLI,
        "run",
        "--junit-xml",
        str(result),
        "--output-file",
        str(disk / "out.log"),
        "--",
        "sh",
        "-c",
        script,
    ]
    done = run_on_tiny_disk(disk, argv, env)
    said = done.stdout.decode(errors="replace")
    assert done.returncode == expected, said + done.stderr.decode(errors="replace")
    assert "after-the-disk-filled" in said  # the console lost nothing
    summary = load_result(result)
    assert "failed" in summary.properties["output_file_error"]
    failed = [case for case in summary.cases if case.outcome in ("error", "failure")]
    assert failed, summary.cases
    text = " ".join(case.message + case.text for case in failed)
    if exit_code == 0:
        assert "output file" in text
    root_text = result.read_text()
    assert "after-the-disk-filled" in root_text  # the output tail is in the result


def test_an_output_file_with_room_passes(env: dict[str, str], tmp_path: Path) -> None:
    """Control: the same run with a disk that has room passes, with no such property."""
    result = tmp_path / "r.xml"
    out = tmp_path / "out.log"
    proc = run_cli(
        [
            "run",
            "--junit-xml",
            str(result),
            "--output-file",
            str(out),
            "--",
            "sh",
            "-c",
            "echo after",
        ],
        env,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = load_result(result)
    assert "output_file_error" not in summary.properties
    assert summary.only.outcome == "passed"
    assert "after" in out.read_text()


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
