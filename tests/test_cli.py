"""The ``run`` command line keeps its promises: typos, bad numbers, clashing files, closed stdio.

Every case runs the real CLI (and the real RUNNER script) as a process; each refusal
has a control showing the same invocation without the mistake goes through.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from helpers.commands import CLI, HUNG, ament, run_cli, run_runner
from helpers.results import load_result

#: A command leaving a file behind, so a test can tell whether it ran.
TOUCH = ("touch", "ran")


def _one_error_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    return lines[0]


# --- A.1: a closed stdout, stderr or stdin never stops the run --------------------------------


@pytest.mark.parametrize("closed", [">&-", "2>&-", "<&-", ">&- 2>&- <&-"])
@pytest.mark.parametrize("mode", ["run", "runner"])
def test_a_closed_standard_stream_still_runs_the_test_and_writes_the_result(
    env: dict[str, str], runner_script: str, tmp_path: Path, closed: str, mode: str
) -> None:
    result = tmp_path / "pkg" / "r.xml"
    command = ["sh", "-c", "touch ran; echo hello; exit 3"]
    if mode == "run":
        argv = [CLI, "run", "--junit-xml", str(result), "--", *command]
    else:
        argv = [sys.executable, "-u", runner_script, str(result), "--command", *command]
    # The shell closes the descriptor, then execs the runner: it starts without it.
    done = subprocess.run(
        ["sh", "-c", f'exec "$@" {closed}', "sh", *argv],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=HUNG,
        check=False,
    )
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 3, done.stdout + done.stderr
    assert (tmp_path / "ran").exists()
    case = load_result(result).only
    assert case.outcome == "failure"
    assert "exited with code 3" in case.message
    if ">&-" not in closed.replace("2>&-", ""):
        assert "hello" in done.stdout  # control: with stdout open, the output is there


# --- A.2: an unknown option before the command is a typo, never the command -------------------


def test_a_mistyped_option_is_a_usage_error_and_nothing_runs(
    env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "r.xml"
    proc = run_cli(
        ["run", "--junit-xml", str(result), "--junit-xlm", "out.xml", "--", *TOUCH],
        env,
        cwd=tmp_path,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    line = _one_error_line(proc.stderr)
    assert "--junit-xlm" in line and "--junit-xml" in line  # named, and the close match
    case = load_result(result).only
    assert case.outcome == "error"
    assert "--junit-xlm" in case.message
    assert not list(Path(env["ROS_ISOLATED_TEST_LOCK_DIR"]).glob("*.holder.json"))


def test_a_mistyped_option_without_a_result_file_is_one_line(
    env: dict[str, str], tmp_path: Path
) -> None:
    proc = run_cli(["run", "--junit-xlm", "out.xml", "--", *TOUCH], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    assert "--junit-xlm" in _one_error_line(proc.stderr)


@pytest.mark.parametrize("separator", [["--"], []])
def test_the_commands_own_options_after_it_still_reach_it(
    env: dict[str, str], tmp_path: Path, separator: list[str]
) -> None:
    """Control of the typo test: an option after the command is the command's."""
    script = 'printf "%s\\n" "$@" > args'
    proc = run_cli(
        ["run", *separator, "sh", "-c", script, "sh", "--anything", "--junit-xlm"],
        env,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "args").read_text().split() == ["--anything", "--junit-xlm"]


# --- A.3 / A.4: numbers of seconds, each option's error naming itself ------------------------


@pytest.mark.parametrize("option", ["--timeout", "--kill-grace", "--wait-timeout"])
@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_nan_and_inf_are_refused_naming_the_option_only(
    env: dict[str, str], tmp_path: Path, option: str, value: str
) -> None:
    result = tmp_path / "r.xml"
    proc = run_cli(
        ["run", "--junit-xml", str(result), f"{option}={value}", "--", *TOUCH], env, cwd=tmp_path
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    line = _one_error_line(proc.stderr)
    assert option in line, line
    assert "ROS_ISOLATED_TEST_WAIT_TIMEOUT" not in line, line
    assert load_result(result).only.outcome == "error"


@pytest.mark.parametrize("option", ["--timeout", "--kill-grace", "--wait-timeout"])
def test_a_finite_number_of_seconds_is_accepted(
    env: dict[str, str], tmp_path: Path, option: str
) -> None:
    """Control: the same options with a plain number run the test."""
    proc = run_cli(["run", f"{option}=30", "--", *TOUCH], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()


# --- A.5: the output file and the result file cannot be one file -----------------------------


def _same_file_spellings(tmp_path: Path) -> dict[str, tuple[str, str]]:
    (tmp_path / "link.xml").symlink_to("r.xml")
    return {
        "identical": ("r.xml", "r.xml"),
        "dot-slash": ("r.xml", "./r.xml"),
        "absolute": ("r.xml", str(tmp_path / "r.xml")),
        "symlink": ("r.xml", "link.xml"),
    }


@pytest.mark.parametrize("spelling", ["identical", "dot-slash", "absolute", "symlink"])
@pytest.mark.parametrize("mode", ["run", "runner"])
def test_output_file_equal_to_the_result_file_is_a_usage_error(
    env: dict[str, str], runner_script: str, tmp_path: Path, spelling: str, mode: str
) -> None:
    result, output = _same_file_spellings(tmp_path)[spelling]
    if mode == "run":
        proc = run_cli(
            ["run", "--junit-xml", result, "--output-file", output, "--", *TOUCH],
            env,
            cwd=tmp_path,
        )
    else:
        proc = ament(runner_script, Path(result), TOUCH, env, "--output-file", output, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert not (tmp_path / "ran").exists()
    line = _one_error_line(proc.stderr)
    assert "--output-file" in line and "result file" in line, line
    assert load_result(tmp_path / "r.xml").only.outcome == "error"


@pytest.mark.parametrize("mode", ["run", "runner"])
def test_distinct_output_and_result_files_both_are_written(
    env: dict[str, str], runner_script: str, tmp_path: Path, mode: str
) -> None:
    """Control: a different output file beside the result file is fine."""
    command = ("sh", "-c", "touch ran; echo hello")
    if mode == "run":
        proc = run_cli(
            ["run", "--junit-xml", "r.xml", "--output-file", "./out.log", "--", *command],
            env,
            cwd=tmp_path,
        )
    else:
        proc = ament(
            runner_script,
            Path("r.xml"),
            command,
            env,
            "--output-file",
            "out.log",
            "--generate-result-on-success",
            cwd=tmp_path,
        )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "hello" in (tmp_path / "out.log").read_text()
    assert load_result(tmp_path / "r.xml").only.outcome == "passed"


# --- --help stays accurate ------------------------------------------------------------------


def test_run_help_names_every_variable_and_exit_code(env: dict[str, str]) -> None:
    proc = run_cli(["run", "--help"], env)
    assert proc.returncode == 0, proc.stderr
    text = " ".join(proc.stdout.split())
    for word in (
        "--wait-timeout",
        "--discovery-range",
        "ROS_ISOLATED_TEST_WAIT_TIMEOUT",
        "ROS_ISOLATED_TEST_DISCOVERY_RANGE",
        "DISABLE_ROS_ISOLATION",
        "--output-file could not be fully written",
        "the --junit-xml or --output-file path cannot be used",
        "--resources",
        "ROS_ISOLATED_TEST_RESOURCES",
        "ROS_ISOLATED_TEST_CAPACITY",
        "124",
        "126/127",
    ):
        assert word in text, word
    top = run_cli(["--help"], env)
    for name in ("ROS_ISOLATED_TEST_DOMAINS", "ROS_ISOLATED_TEST_LOCK_DIR"):
        assert name in top.stdout


# --- an option word is no path: `--junit-xml -- cmd` names no file `--` ----------------------


@pytest.mark.parametrize(
    "options",
    [
        ["--junit-xml", "--"],
        ["--junit-xml=--", "--"],
        ["--output-file", "--"],
        ["--junit-xml", "--timeout", "5", "--"],
        # Empty names no file either, for --junit-xml as for a usage error's result file.
        ["--junit-xml", "", "--"],
        ["--output-file=", "--"],
    ],
)
def test_an_option_word_where_a_path_belongs_is_a_usage_error(
    env: dict[str, str], tmp_path: Path, options: list[str]
) -> None:
    before = set(tmp_path.iterdir())
    proc = run_cli(["run", *options, *TOUCH], env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Running with ROS_DOMAIN_ID" not in proc.stdout
    line = _one_error_line(proc.stderr)
    option = options[0].split("=")[0]
    assert f"'{option}': needs a path" in line, line
    assert set(tmp_path.iterdir()) == before  # nothing ran, no file `--` or `--timeout`


def test_a_file_whose_name_starts_with_a_dash_is_reached_through_dot_slash(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Control: a path given as a path still works, and the command runs."""
    proc = run_cli(["run", "--junit-xml", "./--r.xml", "--", *TOUCH], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ran").exists()
    assert load_result(tmp_path / "--r.xml").only.outcome == "passed"


# --- usage errors read as one clean line -----------------------------------------------------

PREFIX = "ros-isolated-test: error: "


@pytest.mark.parametrize(
    ("mode", "args", "says"),
    [
        ("run", ["run"], "Missing argument 'COMMAND...'; see ros-isolated-test run --help"),
        ("run", ["run", "--timeout", "x", "--", "true"], "'x' is not a valid float range; see"),
        ("run", ["run", "--junit-xml"], "requires an argument; see ros-isolated-test run --help"),
        ("run", ["run", "--discovery-range", "FOO", "--", "true"], "is not a discovery range"),
        ("runner", ["r.xml", "--bogus", "--command", "true"], "unrecognized arguments: --bogus;"),
        ("runner", ["r.xml"], "no test command: pass it after --command (it must come last);"),
    ],
)
def test_a_usage_error_is_one_line_with_one_prefix_and_no_doubled_punctuation(
    env: dict[str, str], runner_script: str, tmp_path: Path, mode: str, args: list[str], says: str
) -> None:
    if mode == "run":
        proc = run_cli(args, env, cwd=tmp_path)
    else:
        proc = run_runner(runner_script, args, env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    line = _one_error_line(proc.stderr)
    assert line.startswith(PREFIX), line
    said = line.removeprefix(PREFIX)
    assert says in said, line
    assert "error:" not in said, line  # one prefix, not "error: ros-isolated-test run: ..."
    assert not said.startswith(("ros-isolated-test", "run_test_isolated.py")), line
    assert ".;" not in said and ";;" not in said and ".." not in said.replace("...", ""), line
