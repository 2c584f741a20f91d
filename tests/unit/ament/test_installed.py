"""``ament.installed``: where this installation keeps what CMake and colcon are pointed at.

``runner-path`` prints the RUNNER script and ``cmake-include`` the CMake file that
CMakeLists.txt files and colcon defaults then name, so each must be right for every way
the package is installed: pip into a prefix (``share/`` beside ``lib/``, which wins), an
editable install or a checkout (the package's own ``cmake/``), or neither (None, for
the CLI to say so). Checked on copies of the package laid out each way, read by a Python
that sees only the copy; the colcon defaults file is read back as YAML, as colcon reads it.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import yaml  # type: ignore[import-untyped]
from helpers.commands import REPO, run_process

from ros_isolated_test.ament import installed

#: Prints where the package it imports finds its CMake include and its RUNNER script.
LOOK_UP = """
from ros_isolated_test.ament import installed
print(installed.cmake_include())
print(installed.runner_script())
"""


def _installed_copy(prefix: Path) -> Path:
    """The package as pip lays it out in ``prefix``, without any CMake file yet: its folder."""
    package = prefix / "lib" / "python3" / "site-packages" / "ros_isolated_test"
    ignored = shutil.ignore_patterns("__pycache__", "cmake")
    shutil.copytree(REPO / "ros_isolated_test", package, ignore=ignored)
    return package


def _look_up(package: Path) -> tuple[str, Path]:
    """What the copy at ``package`` answers, asked by a Python that sees nothing else."""
    done = run_process(
        [sys.executable, "-S", "-c", LOOK_UP], {"PYTHONPATH": str(package.parent)}, cwd=package
    )
    assert done.returncode == 0, done.stderr
    include, script = done.stdout.splitlines()
    return include, Path(script)


def test_the_cmake_include_is_found_for_each_way_of_installing(tmp_path: Path) -> None:
    package = _installed_copy(tmp_path / "prefix")
    name = installed.CMAKE_INCLUDE.name
    # Neither installed nor in the package: None, for the CLI to say so.
    include, script = _look_up(package)
    assert include == "None"
    assert script == package / "ament" / "run_test_isolated.py"  # the copy's own
    # An editable install or a checkout: the package's own cmake/ folder.
    own = package / "cmake" / name
    own.parent.mkdir()
    own.write_text("# the package's own\n")
    assert _look_up(package)[0] == str(own)
    # pip into a prefix: share/ beside lib/, which wins over the package's own.
    shared = tmp_path / "prefix" / installed.CMAKE_INCLUDE
    shared.parent.mkdir(parents=True)
    shared.write_text("# installed by pip\n")
    assert _look_up(package)[0] == str(shared)


def test_the_runner_script_is_the_one_runner_path_prints(runner_script: str) -> None:
    script = installed.runner_script()
    assert script.is_absolute() and script.is_file()
    assert script == Path(runner_script)
    assert script.read_text().startswith('"""ctest RUNNER of ros-isolated-test')


def test_the_colcon_defaults_pass_the_include_to_every_build_whatever_its_path() -> None:
    include = Path('/opt/a "quoted" dir: with # and \\/x.cmake')
    text = installed.colcon_defaults(include)
    assert text.startswith("# colcon defaults (COLCON_DEFAULTS_FILE)")
    read = yaml.safe_load(text)
    assert read == {"build": {"cmake-args": [f"-DCMAKE_PROJECT_INCLUDE={include}"]}}
