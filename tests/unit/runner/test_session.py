"""``session``: the one orchestration path, from a request to the exit code, end to end.

The table of contents of a run, checked in its order: a result path that cannot be used
is refused before anything runs; an --output-file that is the result file is refused
before the placeholder; a skipped test runs nothing and says so; no ID to be had is
exit 3 with a result saying the test never ran; arguments that cannot be understood
still leave a result file. Each refusal beside the run it lets through. Then whole runs
through both entry points: bytes that are not UTF-8 (in the command, an --env value,
the working directory) reach the test as they were, and its result shows them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import CLI, HUNG, run_cli
from helpers.domains import free_ids
from helpers.results import load_result

from ros_isolated_test.domain_coordinator.reservation import DomainCoordinator
from ros_isolated_test.runner import exit_codes, session, settings
from ros_isolated_test.runner.request import Mode, RunRequest


class Ran:
    """One run through ``session.run`` in process: its code, its result, whether the test ran."""

    def __init__(
        self, tmp_path: Path, result_file: Path, domain_id: int | None = None, **given: object
    ) -> None:
        """The run on a pool of ``domain_id`` alone (default: one free now), never waiting."""
        (self.domain_id,) = free_ids(1) if domain_id is None else (domain_id,)
        environ = {
            **os.environ,
            "ROS_ISOLATED_TEST_DOMAINS": str(self.domain_id),
            "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "0",
        }
        self.marker = tmp_path / "ran"
        self.result_file = result_file
        request = RunRequest(
            ("touch", str(self.marker)),
            Mode.SHELL,
            settings.read(environ),
            result_file=result_file,
            generate_result_on_success=True,
            **given,  # type: ignore[arg-type]
        )
        self.request = request
        console = tmp_path / "console"
        with console.open("wb", buffering=0) as stream:
            self.code = session.run(request, stream)
        self.console = console.read_text()

    @property
    def ran(self) -> bool:
        return self.marker.exists()


# --- in process: the steps of a run, each refusal beside its control --------------------------


def test_a_result_path_that_cannot_be_used_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "a folder"
    (folder / "inside").mkdir(parents=True)
    refused = Ran(tmp_path, folder)
    assert (refused.code, refused.ran) == (exit_codes.USAGE, False)
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"ros-isolated-test: error: cannot use result file {folder}: ")
    assert line.endswith("; choose a writable file path"), line
    # The control: a result path that can be used, the test runs and passes.
    accepted = Ran(tmp_path, tmp_path / "pkg" / "t.xml")
    assert (accepted.code, accepted.ran) == (exit_codes.PASSED, True)
    assert load_result(accepted.result_file).only.outcome == "passed"


def test_an_output_file_that_is_the_result_file_is_refused_and_nothing_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    link = tmp_path / "out.log"
    link.symlink_to(result)
    refused = Ran(tmp_path, result, output_file=link)
    assert (refused.code, refused.ran) == (exit_codes.USAGE, False)
    (line,) = capsys.readouterr().err.splitlines()
    case = load_result(result).only
    assert case.outcome == "error" and line == f"ros-isolated-test: error: {case.message}"
    assert f"--output-file {link} is the result file {result}" in case.message
    assert load_result(result).properties["exit"] == "not run"
    # The control: another output file, the test runs and its output file is written.
    other = tmp_path / "other.log"
    accepted = Ran(tmp_path, result, output_file=other)
    assert (accepted.code, accepted.ran) == (exit_codes.PASSED, True)
    assert "invoking in" in other.read_text()


def test_a_skipped_test_runs_nothing_and_its_result_says_so(tmp_path: Path) -> None:
    result = tmp_path / "pkg" / "t.xml"
    skipped = Ran(tmp_path, result, skip_test=True)
    assert (skipped.code, skipped.ran) == (exit_codes.PASSED, False)
    case = load_result(result).only
    assert (case.outcome, case.message) == ("skipped", "Test skipped by developer (SKIP_TEST)")
    assert "skipping the test (--skip-test)" in skipped.console
    assert "Running with ROS_DOMAIN_ID" not in skipped.console  # nothing reserved either


def test_no_id_to_be_had_is_exit_3_and_a_result_saying_the_test_never_ran(
    tmp_path: Path, lock_dir: Path
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    (domain_id,) = free_ids(1)
    with DomainCoordinator(lock_dir, [domain_id]).reserve(["the holder"]):
        refused = Ran(tmp_path, result, domain_id)
    assert (refused.code, refused.ran) == (exit_codes.NO_DOMAIN, False)
    summary = load_result(result)
    assert summary.only.outcome == "error" and summary.properties["exit"] == "not run"
    # The control: the ID released, the same run goes ahead.
    accepted = Ran(tmp_path, result, domain_id)
    assert (accepted.code, accepted.ran) == (exit_codes.PASSED, True)


def test_arguments_that_cannot_be_understood_still_leave_a_result_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = tmp_path / "pkg" / "t.xml"
    assert session.report_usage_error("no test command given", result) == exit_codes.USAGE
    assert capsys.readouterr().err == "ros-isolated-test: error: no test command given\n"
    summary = load_result(result)
    assert (summary.only.outcome, summary.only.message) == ("error", "no test command given")
    assert summary.properties["exit"] == "not run"
    # Without a result file to leave (none named), the line alone.
    assert session.report_usage_error("no result file", None) == exit_codes.USAGE
    assert capsys.readouterr().err == "ros-isolated-test: error: no result file\n"


# --- real runs: usage errors, and bytes that are not UTF-8 ------------------------------------


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


LATIN1 = b"caf\xe9"


def _bytes_run(
    argv: list[bytes], env: dict[str, str], cwd: Path
) -> subprocess.CompletedProcess[bytes]:
    """A runner process with bytes arguments; its output as bytes (the test echoes Latin-1)."""
    return subprocess.run(argv, env=env, cwd=cwd, capture_output=True, timeout=HUNG, check=False)


@pytest.mark.parametrize("where", ["argument", "--env", "cwd", "shell argument", "shell cwd"])
def test_bytes_that_are_not_utf8_reach_the_test_and_its_result_shows_them(
    env: dict[str, str], runner_script: str, tmp_path: Path, where: str
) -> None:
    """Python carries them as lone surrogates: the runner's lines and result show ``\\xe9``."""
    result = tmp_path / "t.xml"
    cwd = tmp_path
    # Writes what it got: its argument, $BAD, its working directory.
    test = [b"sh", b"-c", b'printf "%s|%s|%s" "$1" "$BAD" "$PWD" > "$0/seen"', bytes(tmp_path)]
    test.append(LATIN1 if where.endswith("argument") else b"-")
    options: list[bytes] = []
    if where == "--env":
        options = [b"--env", b"BAD=" + LATIN1]
    elif where.endswith("cwd"):
        cwd = Path(os.fsdecode(bytes(tmp_path) + b"/dir-" + LATIN1))
        cwd.mkdir()
    if where.startswith("shell"):
        argv = [os.fsencode(CLI), b"run", b"--junit-xml", bytes(result), b"--", *test]
    else:
        argv = [os.fsencode(sys.executable), b"-u", os.fsencode(runner_script), bytes(result)]
        argv += [b"--package-name", b"pkg", b"--generate-result-on-success", *options]
        argv += [b"--command", *test]

    done = _bytes_run(argv, env, cwd)

    assert done.returncode == 0, done.stdout + done.stderr
    assert b"Traceback" not in done.stderr
    assert LATIN1 in (tmp_path / "seen").read_bytes(), "the test got the bytes as they were"
    summary = load_result(result)
    assert summary.only.outcome == "passed"
    assert "not generate" not in result.read_text(), "the placeholder was left"
    if where == "--env":
        shown = b" - BAD=caf\\xe9\n"
    elif where.endswith("cwd"):
        shown = b"/dir-caf\\xe9': "
    else:
        shown = b" 'caf\\xe9'\n"  # quoted as shlex quotes any non-ASCII word
        assert summary.properties["command"].endswith(" 'caf\\xe9'")
    assert shown in done.stdout, "shown in the runner's lines, never raw"
    assert LATIN1 not in done.stdout


def test_control_utf8_arguments_are_shown_as_they_are(
    env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    result = tmp_path / "t.xml"
    argv = [os.fsencode(sys.executable), b"-u", os.fsencode(runner_script), bytes(result)]
    argv += [b"--generate-result-on-success", b"--command", b"echo", "café".encode()]
    done = _bytes_run(argv, env, tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "café" in load_result(result).properties["command"]
    assert "echo 'café'\n".encode() in done.stdout
