from __future__ import annotations

import subprocess
from pathlib import Path

from ros_isolated_test.colcon import project_include


def test_the_arguments_name_the_stable_file_and_the_installed_include(tmp_path: Path) -> None:
    include = tmp_path / "share" / "x.cmake"
    before, named = project_include.cmake_args(tmp_path / "build", include)
    folder = tmp_path / "build" / project_include.FOLDER
    assert before == f"-DCMAKE_PROJECT_INCLUDE_BEFORE={folder / project_include.BEFORE}"
    assert named == f"-D{project_include.INCLUDE_VARIABLE}={include}"


def test_written_once_and_never_touched_again_when_unchanged(tmp_path: Path) -> None:
    folder = project_include.write(tmp_path)
    files = sorted(folder.iterdir())
    assert [path.name for path in files] == [project_include.AFTER, project_include.BEFORE]
    stamps = [path.stat().st_mtime_ns for path in files]
    inodes = [path.stat().st_ino for path in files]
    project_include.write(tmp_path)
    assert [path.stat().st_mtime_ns for path in files] == stamps
    assert [path.stat().st_ino for path in files] == inodes


def test_a_changed_file_is_written_again(tmp_path: Path) -> None:
    folder = project_include.write(tmp_path)
    (folder / project_include.AFTER).write_text("# edited\n")
    project_include.write(tmp_path)
    assert (folder / project_include.AFTER).read_text() == project_include.AFTER_TEXT


def _configure(tmp_path: Path, include: Path, env: dict[str, str]) -> str:
    """A real CMake project configured through the stable files (no ament: a plain project)."""
    source = tmp_path / "src"
    source.mkdir(exist_ok=True)
    (source / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.15)\nproject(p NONE)\n"
    )
    own = tmp_path / "own.cmake"
    own.write_text('message(STATUS "own ran")\n')
    project_include.write(tmp_path / "build")
    build = tmp_path / "build" / "p"
    build.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(
        ["cmake", str(source), f"-DCMAKE_PROJECT_INCLUDE={own}",
         *project_include.cmake_args(tmp_path / "build", include)],
        cwd=build, env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return done.stdout


def test_the_installed_include_and_the_projects_own_both_run(
    tmp_path: Path, env: dict[str, str]
) -> None:
    include = tmp_path / "installed.cmake"
    include.write_text('message(STATUS "installed ran")\n')
    out = _configure(tmp_path, include, env)
    assert out.index("installed ran") < out.index("own ran")
    assert "NOT isolated" not in out


def test_gone_installation_is_said_and_the_own_include_still_runs(
    tmp_path: Path, env: dict[str, str]
) -> None:
    out = _configure(tmp_path, tmp_path / "uninstalled.cmake", env)
    assert out.count("are NOT isolated: ros-isolated-test is no longer installed") == 1
    assert "own ran" in out


def test_off_at_configure_time_runs_only_the_own_include(
    tmp_path: Path, env: dict[str, str]
) -> None:
    include = tmp_path / "installed.cmake"
    include.write_text('message(STATUS "installed ran")\n')
    out = _configure(tmp_path, include, {**env, "ROS_ISOLATED_TEST_COLCON": "Off"})
    assert "installed ran" not in out and "NOT isolated" not in out
    assert "own ran" in out
