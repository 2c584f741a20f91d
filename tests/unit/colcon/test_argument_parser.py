from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from ros_isolated_test.ament import installed
from ros_isolated_test.colcon import argument_parser, project_include


def _parsed(tmp_path: Path, verb: str = "build", **more: object) -> argparse.Namespace:
    return argparse.Namespace(
        verb_name=verb, build_base=str(tmp_path / "build"), ament_cmake_args=None, **more
    )


def test_build_gains_the_stable_include_after_the_users_own_arguments(tmp_path: Path) -> None:
    parsed = _parsed(tmp_path)
    parsed.ament_cmake_args = ["-DMINE=1"]
    argument_parser.add_include(parsed)
    include = installed.cmake_include()
    assert include is not None
    assert parsed.ament_cmake_args == [
        "-DMINE=1",
        *project_include.cmake_args(tmp_path / "build", include),
    ]
    assert (tmp_path / "build" / project_include.FOLDER / project_include.BEFORE).is_file()


def test_the_same_arguments_each_time(tmp_path: Path) -> None:
    first, second = _parsed(tmp_path), _parsed(tmp_path)
    argument_parser.add_include(first)
    argument_parser.add_include(second)
    assert first.ament_cmake_args == second.ament_cmake_args


def test_other_verbs_are_left_alone(tmp_path: Path) -> None:
    parsed = _parsed(tmp_path, verb="test")
    argument_parser.add_include(parsed)
    assert parsed.ament_cmake_args is None
    assert not (tmp_path / "build").exists()


def test_off_leaves_the_build_as_without_us(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROS_ISOLATED_TEST_COLCON", "off")
    parsed = _parsed(tmp_path)
    argument_parser.add_include(parsed)
    assert parsed.ament_cmake_args is None
    assert not (tmp_path / "build").exists()


def test_control_on_by_default(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The suite sets the switch off for its colcon runs (conftest); unset, it is on."""
    monkeypatch.delenv("ROS_ISOLATED_TEST_COLCON", raising=False)
    parsed = _parsed(tmp_path)
    argument_parser.add_include(parsed)
    assert parsed.ament_cmake_args


def test_the_decorator_adds_it_to_what_colcon_parses(tmp_path: Path) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--build-base", default=str(tmp_path / "build"))
    parser.add_argument("--ament-cmake-args", nargs="*", type=str.lstrip)
    parser.set_defaults(verb_name="build")
    decorated = argument_parser.ProjectIncludeArgumentParserDecorator().decorate_argument_parser(
        parser=parser
    )
    parsed = decorated.parse_args(["--ament-cmake-args", " -DMINE=1"])
    assert parsed.ament_cmake_args[0] == "-DMINE=1"
    assert parsed.ament_cmake_args[1].startswith("-DCMAKE_PROJECT_INCLUDE_BEFORE=")
