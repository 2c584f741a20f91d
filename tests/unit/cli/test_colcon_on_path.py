"""``cli.colcon_on_path``: does the colcon on PATH load our colcon extension?

Asked of real colcons: the suite's venv's, where the project is installed (it loads it),
and the distro venv's, whose Python lacks the project (the control: it does not, as
``colcon extensions`` there shows too). Each shebang form a console script has (a path,
``/usr/bin/env``, pip's ``/bin/sh`` exec line for long paths) is read on scripts that
start those same two Pythons; a PATH with no colcon says so. ``status`` prints the line
after its table, and on stderr with ``--json`` (its stdout stays JSON).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import run_cli
from helpers.ros_package import DISTRO_VENV

from ros_isolated_test.cli import colcon_on_path

VENV_BIN = Path(sys.prefix) / "bin"
DISTRO_BIN = DISTRO_VENV.bin
LOADS = "loads ros-isolated-test's extension"
DOES_NOT = "does not load ros-isolated-test's extension: install ros-isolated-test into"


def _path(*folders: Path) -> str:
    return os.pathsep.join([*map(str, folders), "/usr/bin", "/bin"])


def _script(folder: Path, head: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    script = folder / "colcon"
    script.write_text(f"{head}\nimport sys\nfrom colcon_core.command import main\n")
    script.chmod(0o755)
    return script


@capabilities.COLCON.mark
def test_the_suites_colcon_loads_it(env: dict[str, str]) -> None:
    said = colcon_on_path.said({**env, "PATH": _path(VENV_BIN)})
    assert said == f"colcon: colcon on PATH ({VENV_BIN / 'colcon'}) {LOADS}"


@capabilities.DISTRO_VENV.mark
def test_a_colcon_whose_python_lacks_the_project_does_not_and_says_where_to_install(
    env: dict[str, str],
) -> None:
    """The control: colcon's own listing agrees that this colcon has no ros_isolated_test."""
    listed = subprocess.run(
        [str(DISTRO_BIN / "colcon"), "extensions"], env={**env, "PATH": _path(DISTRO_BIN)},
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert "ros_isolated_test" not in listed.stdout and "colcon_core.event_handler" in listed.stdout
    said = colcon_on_path.said({**env, "PATH": _path(DISTRO_BIN)})
    assert said == (
        f"colcon: colcon on PATH ({DISTRO_BIN / 'colcon'}) {DOES_NOT} colcon's Python "
        f"({DISTRO_BIN / 'python'}), see docs/install.md"
    )


@capabilities.DISTRO_VENV.mark
@pytest.mark.parametrize(
    ("head", "loads"),
    [
        ("#!/usr/bin/env python", True),
        ("#!/usr/bin/env -S python -s", True),
        ("#!/bin/sh\n'''exec' \"{distro}\" \"$0\" \"$@\"\n' '''", False),
        ("#!{distro}", False),
    ],
    ids=["env", "env-with-options", "pip-long-path", "path"],
)
def test_every_shebang_form_is_read(
    tmp_path: Path, env: dict[str, str], head: str, loads: bool
) -> None:
    """``env`` finds python on PATH (the suite's venv first); the others name the distro's."""
    script = _script(tmp_path / "bin", head.format(distro=DISTRO_BIN / "python"))
    path = _path(tmp_path / "bin", VENV_BIN)
    python = colcon_on_path.script_python(script, path)
    assert python == str(VENV_BIN / "python" if loads else DISTRO_BIN / "python")
    said = colcon_on_path.said({**env, "PATH": path})
    assert said.startswith(f"colcon: colcon on PATH ({script}) ")
    assert (LOADS in said, DOES_NOT in said) == (loads, not loads), said


def test_no_colcon_on_path_is_said(tmp_path: Path, env: dict[str, str]) -> None:
    assert colcon_on_path.said({**env, "PATH": str(tmp_path)}) == "colcon: no colcon on PATH"


def test_a_script_with_no_shebang_names_no_python_and_says_how_to_check(
    tmp_path: Path, env: dict[str, str]
) -> None:
    script = _script(tmp_path, "# no shebang")
    assert colcon_on_path.script_python(script, str(tmp_path)) is None
    said = colcon_on_path.said({**env, "PATH": str(tmp_path)})
    assert said.startswith(f"colcon: cannot tell which Python colcon on PATH ({script}) runs")
    assert "colcon extensions | grep ros_isolated_test" in said


@capabilities.COLCON.mark
def test_status_says_it_on_stderr_and_leaves_stdout_to_the_table_or_json(
    tmp_path: Path, env: dict[str, str]
) -> None:
    here = {**env, "PATH": _path(VENV_BIN)}
    table = run_cli(["status"], here, cwd=tmp_path)
    assert table.returncode == 0, table.stderr
    loads = f"colcon: colcon on PATH ({VENV_BIN / 'colcon'}) {LOADS}"
    assert loads in table.stderr.splitlines()
    assert not any(line.startswith("colcon:") for line in table.stdout.splitlines())
    as_json = run_cli(["status", "--json"], here, cwd=tmp_path)
    assert as_json.returncode == 0, as_json.stderr
    json.loads(as_json.stdout)  # still parseable
    assert loads in as_json.stderr.splitlines()
    none = run_cli(["status"], {**env, "PATH": str(tmp_path)}, cwd=tmp_path)
    assert "colcon: no colcon on PATH" in none.stderr.splitlines()
