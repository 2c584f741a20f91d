"""``history``'s command line: one-line usage errors, the default subcommand, no database."""

from __future__ import annotations

from pathlib import Path

from helpers.commands import run_cli, the_error_line


def test_usage_errors_are_one_line_exit_2(env: dict[str, str], tmp_path: Path) -> None:
    for args in (["history", "--bogus"], ["history", "record"], ["history", "merge", "x"]):
        proc = run_cli(args, env, cwd=tmp_path)
        assert proc.returncode == 2, args
        assert "see ros-isolated-test history" in the_error_line(proc)


def test_no_database_is_one_line_naming_it(env: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(["history"], {**env, "ROS_ISOLATED_TEST_HISTORY": str(tmp_path / "h.db")})
    assert proc.returncode == 1
    assert str(tmp_path / "h.db") in the_error_line(proc)
    help_text = run_cli(["history", "--help"], env)  # control: the group still helps
    assert help_text.returncode == 0 and "record" in help_text.stdout
