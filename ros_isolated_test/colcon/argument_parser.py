"""The ``colcon_core.argument_parser`` entry: ``colcon build`` isolates ament_cmake packages.

An argument parser decorator is the one colcon extension that sees the parsed command
line, so the one that knows the build base the stable include lives in. For ``colcon
build`` it writes that include (``project_include``) and appends its two CMake
arguments to ``--ament-cmake-args``, which colcon's ament_cmake task adds after the
user's own ``--cmake-args`` (and a ``colcon.meta`` or defaults file's, which extend
the list): nothing of the user's is dropped, and the same arguments each build let
colcon keep a package's configuration. Other verbs, and plain CMake packages, are left
alone. It prints nothing: each package's configure line says it is isolated.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import MutableMapping
from pathlib import Path
from typing import Any

from colcon_core.argument_parser import (  # type: ignore[import-untyped]
    ArgumentParserDecorator,
    ArgumentParserDecoratorExtensionPoint,
)
from colcon_core.logging import colcon_logger  # type: ignore[import-untyped]
from colcon_core.plugin_system import satisfies_version  # type: ignore[import-untyped]

from ros_isolated_test import names
from ros_isolated_test.colcon import project_include, switch

logger = colcon_logger.getChild(__name__)


class ProjectIncludeArgumentParserDecorator(ArgumentParserDecoratorExtensionPoint):  # type: ignore[misc]
    """Give every ament_cmake package of ``colcon build`` ros-isolated-test's include."""

    def __init__(self) -> None:
        super().__init__()
        satisfies_version(ArgumentParserDecoratorExtensionPoint.EXTENSION_POINT_VERSION, "^1.0")

    def decorate_argument_parser(self, *, parser: Any) -> Any:
        return _ProjectIncludeDecorator(parser)


class _ProjectIncludeDecorator(ArgumentParserDecorator):  # type: ignore[misc]
    """The parser, whose parsed ``colcon build`` arguments gain the include."""

    def parse_args(self, *args: Any, **kwargs: Any) -> argparse.Namespace:
        parsed: argparse.Namespace = self._parser.parse_args(*args, **kwargs)
        add_include(parsed)
        one_history_recorder(parsed, os.environ)
        return parsed


def one_history_recorder(parsed: argparse.Namespace, environ: MutableMapping[str, str]) -> None:
    """For ``colcon test``: the run is recorded once, whole, by the summary at its end.

    colcon's environment is its tests' environment: ``ROS_ISOLATED_TEST_HISTORY_BY_COLCON``
    tells ``run`` and the pytest plugin under it to record nothing of their own (each
    would be a run of its own), and ``ROS_ISOLATED_TEST_HISTORY``, when the user named
    none, becomes the workspace's database (absolute), which the summary records into and
    the runners' flaky reruns read.
    """
    if getattr(parsed, "verb_name", None) != "test" or not switch.state(environ)[0]:
        return
    environ[names.HISTORY_BY_COLCON] = "1"
    if not environ.get(names.HISTORY, ""):
        from ros_isolated_test.history.store import DEFAULT_FILE

        environ[names.HISTORY] = os.path.abspath(DEFAULT_FILE)


def add_include(parsed: argparse.Namespace) -> None:
    """Append the stable include's arguments to a ``colcon build``'s ``ament_cmake_args``."""
    if getattr(parsed, "verb_name", None) != "build" or not hasattr(parsed, "ament_cmake_args"):
        return
    on, problem = switch.state(os.environ)
    if problem is not None:
        logger.warning(problem)
    if not on:
        return
    from ros_isolated_test.ament import installed

    include = installed.cmake_include()
    if include is None:
        logger.warning(
            "ros-isolated-test's CMake include is not installed beside it: tests of "
            "ament_cmake packages are not isolated; reinstall ros-isolated-test"
        )
        return
    build_base = Path(parsed.build_base)
    try:
        project_include.write(build_base)
    except OSError as error:
        logger.warning(
            f"ros-isolated-test cannot write its include into {build_base}: {error}; "
            "tests of ament_cmake packages are not isolated"
        )
        return
    parsed.ament_cmake_args = [
        *(parsed.ament_cmake_args or []),
        *project_include.cmake_args(build_base, include),
    ]
