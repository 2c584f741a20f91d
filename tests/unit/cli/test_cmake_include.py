"""``cli.cmake_include``: the include's path, a defaults file naming it, and a FILE it refuses."""

from __future__ import annotations

from pathlib import Path

from helpers.commands import run_cli, the_error_line

from ros_isolated_test.cli import usage


def test_the_include_and_a_new_defaults_file_name_the_same_existing_file(
    env: dict[str, str], tmp_path: Path
) -> None:
    proc = run_cli(["cmake-include"], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    include = Path(proc.stdout.strip())
    assert include.is_file() and include.suffix == ".cmake"
    defaults = run_cli(["cmake-include", "--colcon-defaults"], env, cwd=tmp_path)
    assert defaults.returncode == 0, defaults.stderr
    assert f"-DCMAKE_PROJECT_INCLUDE={include}" in defaults.stdout


def test_a_defaults_file_it_cannot_change_is_left_and_the_lines_printed(
    env: dict[str, str], tmp_path: Path
) -> None:
    broken = tmp_path / "defaults.yaml"
    broken.write_text("build: [not, a, mapping\n")
    proc = run_cli(["cmake-include", "--colcon-defaults", str(broken)], env, cwd=tmp_path)
    assert proc.returncode == usage.FAILED, proc.stderr
    assert str(broken) in the_error_line(proc)
    assert broken.read_text() == "build: [not, a, mapping\n"
    assert "CMAKE_PROJECT_INCLUDE" in proc.stdout
