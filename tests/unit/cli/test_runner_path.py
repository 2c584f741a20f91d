"""``cli.runner_path``: ``runner-path`` prints the RUNNER script a CMakeLists.txt names."""

from __future__ import annotations

from pathlib import Path

from helpers.commands import run_cli


def test_runner_path_prints_an_existing_absolute_python_file(
    env: dict[str, str], tmp_path: Path
) -> None:
    proc = run_cli(["runner-path"], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    path = Path(proc.stdout.strip())
    assert proc.stdout == f"{path}\n"
    assert path.is_absolute()
    assert path.suffix == ".py"
    assert path.is_file()
