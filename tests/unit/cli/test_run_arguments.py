"""``cli.run``'s arguments: typos, bad numbers, option words, one-line usage errors.

What click parses before anything runs: an unknown option before the command is a typo,
never the command; nan and inf are no number of seconds; an option word is no path; every
usage error is one clean line (and still the --junit-xml file asked for). Every case
runs the real CLI (and, where the promise is shared, the real RUNNER script) as a
process; each refusal has a control showing the same invocation without the mistake
goes through.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.cli_runs import TOUCH
from helpers.commands import run_cli, run_runner, the_error_line
from helpers.results import load_result

# --- A.2: an unknown option before the command is a typo, never the command ----------------------


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
    line = the_error_line(proc)
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
    assert "--junit-xlm" in the_error_line(proc)


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


def test_runner_options_after_the_double_dash_go_to_the_command(
    env: dict[str, str], tmp_path: Path
) -> None:
    proc = run_cli(
        ["run", "--", "sh", "-c", 'echo "seen $*"', "sh", "--timeout", "1", "--help"],
        env,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seen --timeout 1 --help\n" in proc.stdout


# --- A.3 / A.4: numbers of seconds, each option's error naming itself ----------------------------


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
    line = the_error_line(proc)
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


# --- an option word is no path: `--junit-xml -- cmd` names no file `--` --------------------------


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
    line = the_error_line(proc)
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


# --- usage errors read as one clean line ---------------------------------------------------------

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
    line = the_error_line(proc)
    assert line.startswith(PREFIX), line
    said = line.removeprefix(PREFIX)
    assert says in said, line
    assert "error:" not in said, line  # one prefix, not "error: ros-isolated-test run: ..."
    assert not said.startswith(("ros-isolated-test", "run_test_isolated.py")), line
    assert ".;" not in said and ";;" not in said and ".." not in said.replace("...", ""), line


@pytest.mark.parametrize("args", [["run"], ["run", "--"], ["run", "--junit-xml", "x.xml"]])
def test_missing_command_is_a_usage_error(
    env: dict[str, str], tmp_path: Path, args: list[str]
) -> None:
    proc = run_cli(args, env, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Missing argument" in proc.stderr
    if "--junit-xml" in args:
        # Nothing ran, and the result file asked for says why.
        case = load_result(tmp_path / "x.xml").only
        assert case.outcome == "error"
        assert "Missing argument" in case.message
    else:
        assert not (tmp_path / "x.xml").exists()
