"""The RUNNER script itself: a few lines that hand over, since every test compiles it anew.

A script run by path has no cached bytecode, so whatever it holds is compiled for every
test ctest starts. What it does without the package lives in ``without_package.py``
(tested in test_without_package.py), read only when the import fails.
"""

from __future__ import annotations

import ast
from pathlib import Path

from helpers.commands import ament
from helpers.results import load_result

#: More than the hand-over and the exit needs, and far less than the fallback was.
MOST_LINES = 60


def test_the_script_only_hands_over(runner_script: str) -> None:
    source = Path(runner_script).read_text(encoding="utf-8")
    assert len(source.splitlines()) <= MOST_LINES
    tree = ast.parse(source)
    imported = {
        alias.name for node in tree.body if isinstance(node, ast.Import) for alias in node.names
    }
    assert imported == {"gc", "os", "sys"}  # all three built in
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert functions == {"_import_main", "_exit"}
    assert (Path(runner_script).parent / "without_package.py").is_file()


def test_control_a_test_through_the_script_runs_and_passes(
    runner_script: str, env: dict[str, str], tmp_path: Path
) -> None:
    result = tmp_path / "t.xml"
    proc = ament(
        runner_script, result, ("true",), env, "--generate-result-on-success", cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert load_result(result).only.outcome == "passed"
