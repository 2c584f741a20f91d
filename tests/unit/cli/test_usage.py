"""``cli.usage``: every usage error is one line, ``ros-isolated-test: error: <problem>; <fix>``.

Each subcommand of the group (the list is read from the group, so a new command is
covered or fails here), the group itself, ``history``'s subcommands, the errors a
command raises itself, and the RUNNER: one line on stderr, naming the command's
``--help``, with the exit code docs/reference.md gives a usage error. The control: each
command's ``--help`` still prints click's help, exit 0.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from helpers.commands import REPO, run_cli, run_runner, the_error_line

from ros_isolated_test.cli import cli, usage

#: One unknown option per command: the same mistake everywhere.
BOGUS = "--no-such-option"
#: Errors a command finds itself, after click parsed its arguments.
RAISED = {
    "report": (["report"], "no PATHS given and no 'build' folder here"),
    "shard": (["shard", "--total", "2"], "say what to show: --plan"),
    "cmake-include": (["cmake-include", "x.yaml"], "FILE is the colcon defaults file"),
    "history": (["history", "merge", "x"], "File 'x' does not exist"),
    "group": (["no-such-command"], "No such command 'no-such-command'"),
}


def _usage_code_in_the_reference() -> int:
    """The code docs/reference.md's exit-code table gives bad arguments."""
    text = (REPO / "docs" / "reference.md").read_text(encoding="utf-8")
    found = re.findall(r"^\| (\d+) \| nothing was run: bad arguments", text, re.M)
    assert len(found) == 1, "docs/reference.md names no exit code for a usage error"
    return int(found[0])


def _one_line(proc: subprocess.CompletedProcess[str], command: str) -> str:
    line = the_error_line(proc)
    assert line.startswith(usage.PREFIX)
    assert line.endswith(f"; see {command} --help"), line
    assert ".;" not in line, line
    return line


def test_the_reference_names_the_code_the_commands_exit_with() -> None:
    assert _usage_code_in_the_reference() == usage.USAGE == 2


@pytest.mark.parametrize("name", sorted(cli.commands))
def test_every_subcommands_usage_error_is_one_line(
    env: dict[str, str], tmp_path: Path, name: str
) -> None:
    proc = run_cli([name, BOGUS], env, cwd=tmp_path)
    assert proc.returncode == _usage_code_in_the_reference(), proc.stderr
    path = f"ros-isolated-test {name}" + (" show" if name == "history" else "")
    assert BOGUS in _one_line(proc, path)
    assert proc.stdout == ""
    helped = run_cli([name, "--help"], env, cwd=tmp_path)  # control: help is click's own
    assert helped.returncode == 0, helped.stderr
    assert helped.stdout.startswith("Usage: ")


@pytest.mark.parametrize("case", sorted(RAISED))
def test_an_error_a_command_finds_itself_is_the_same_one_line(
    env: dict[str, str], tmp_path: Path, case: str
) -> None:
    args, says = RAISED[case]
    proc = run_cli(args, env, cwd=tmp_path)
    assert proc.returncode == usage.USAGE, proc.stderr
    command = {"group": "ros-isolated-test", "history": "ros-isolated-test history merge"}
    line = _one_line(proc, command.get(case, f"ros-isolated-test {args[0]}"))
    assert says in line


def test_the_groups_own_option_error_is_one_line(env: dict[str, str]) -> None:
    proc = run_cli([BOGUS], env)
    assert proc.returncode == usage.USAGE
    assert BOGUS in _one_line(proc, "ros-isolated-test")
    helped = run_cli(["--help"], env)  # control
    assert helped.returncode == 0 and helped.stdout.startswith("Usage: ")


def test_the_runners_usage_error_is_the_same_one_line(
    env: dict[str, str], runner_script: str, tmp_path: Path
) -> None:
    proc = run_runner(runner_script, [str(tmp_path / "r.xml"), BOGUS], env, cwd=tmp_path)
    assert proc.returncode == _usage_code_in_the_reference()
    assert BOGUS in _one_line(proc, "run_test_isolated.py")
    assert (tmp_path / "r.xml").is_file()  # and the result file says why
