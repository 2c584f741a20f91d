"""The stable include colcon hands every ament_cmake package, in colcon's build base.

colcon configures a package again only when its CMake arguments differ from the last
build's, and CMake keeps an include's path in the package's cache. So the path colcon
passes must never change, and the file behind it must stay valid whatever happens to
the installation: upgraded, moved to another venv, uninstalled. Two small files in
``<build base>/.ros_isolated_test/`` (a hidden folder: colcon and ``report`` skip it)
do that. ``CMAKE_PROJECT_INCLUDE_BEFORE`` names the first; before each ``project()``
it makes CMake include the second right after that call, and remembers the package's
own ``CMAKE_PROJECT_INCLUDE``. The second includes the installed project include
(``ROS_ISOLATED_TEST_COLCON_INCLUDE``, passed beside it) only if that still exists,
else says once that the package's tests are not isolated, then includes the
package's own file: both run. With ``ROS_ISOLATED_TEST_COLCON`` off at configure time
they only chain the package's own file, as if we were not there.

The files' text depends on nothing installed: written only when it differs, so a
second build finds them unchanged and neither colcon nor the build tool reconfigures.
"""

from __future__ import annotations

import os
from pathlib import Path

from ros_isolated_test.atomic_file import write_atomically
from ros_isolated_test.switches import OFF_WORDS

FOLDER = ".ros_isolated_test"
BEFORE = "project_include_before.cmake"
AFTER = "project_include_after.cmake"
#: The cache variable naming the installed project include.
INCLUDE_VARIABLE = "ROS_ISOLATED_TEST_COLCON_INCLUDE"
#: What the project include says of how it was turned on, and what the colcon route says.
_HOW_INCLUDE = "(CMAKE_PROJECT_INCLUDE; -DROS_ISOLATED_TEST_ALL=OFF turns it off)"
HOW_COLCON = "(ros-isolated-test's colcon extension; ROS_ISOLATED_TEST_COLCON=off turns it off)"
_OFF = "|".join(sorted(OFF_WORDS))

_SWITCH = """\
string(TOLOWER "$ENV{ROS_ISOLATED_TEST_COLCON}" _ros_isolated_test_colcon)
string(STRIP "${_ros_isolated_test_colcon}" _ros_isolated_test_colcon)
"""

BEFORE_TEXT = f"""\
# Written by ros-isolated-test's colcon extension; colcon passes it to every ament_cmake
# package as CMAKE_PROJECT_INCLUDE_BEFORE. Before each project() call it has CMake
# include {AFTER} right after that call, which includes the installed
# project include ({INCLUDE_VARIABLE}) if it still exists, then the package's own
# CMAKE_PROJECT_INCLUDE. ROS_ISOLATED_TEST_COLCON=off: only the package's own.
{_SWITCH}if(NOT _ros_isolated_test_colcon MATCHES "^({_OFF})$"
    AND NOT "${{CMAKE_PROJECT_INCLUDE}}" STREQUAL "${{CMAKE_CURRENT_LIST_DIR}}/{AFTER}")
  set(_ros_isolated_test_colcon_own "${{CMAKE_PROJECT_INCLUDE}}")
  set(CMAKE_PROJECT_INCLUDE "${{CMAKE_CURRENT_LIST_DIR}}/{AFTER}")
endif()
unset(_ros_isolated_test_colcon)
"""

AFTER_TEXT = f"""\
# Written by ros-isolated-test's colcon extension: see {BEFORE}.
unset(CMAKE_PROJECT_INCLUDE)  # the package's own (cached) value is seen again
if(NOT "${{{INCLUDE_VARIABLE}}}" STREQUAL "" AND EXISTS "${{{INCLUDE_VARIABLE}}}")
  # Another installation than the last configure's (or its command gone): the command
  # cached for it is searched again, this installation's first.
  if(NOT "$CACHE{{_ROS_ISOLATED_TEST_COLCON_LAST}}" STREQUAL "${{{INCLUDE_VARIABLE}}}"
      OR NOT EXISTS "$CACHE{{ROS_ISOLATED_TEST_EXECUTABLE}}")
    unset(ROS_ISOLATED_TEST_EXECUTABLE CACHE)
    set(_ROS_ISOLATED_TEST_COLCON_LAST "${{{INCLUDE_VARIABLE}}}" CACHE INTERNAL "")
  endif()
  include("${{{INCLUDE_VARIABLE}}}")
  get_property(_ros_isolated_test_colcon GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_SAY)
  string(REPLACE "{_HOW_INCLUDE}" "{HOW_COLCON}"
    _ros_isolated_test_colcon "${{_ros_isolated_test_colcon}}")
  set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_ALL_SAY "${{_ros_isolated_test_colcon}}")
else()
  get_property(_ros_isolated_test_colcon GLOBAL PROPERTY _ROS_ISOLATED_TEST_COLCON_SAID)
  if(NOT _ros_isolated_test_colcon)
    set_property(GLOBAL PROPERTY _ROS_ISOLATED_TEST_COLCON_SAID TRUE)
    message(STATUS "ros_isolated_test: tests of ${{PROJECT_NAME}} are NOT isolated: "
      "ros-isolated-test is no longer installed where this build was configured with it "
      "(${{{INCLUDE_VARIABLE}}} is gone); install it where colcon runs to isolate them again")
  endif()
endif()
unset(_ros_isolated_test_colcon)
if(NOT "${{_ros_isolated_test_colcon_own}}" STREQUAL "")
  include("${{_ros_isolated_test_colcon_own}}")
endif()
unset(_ros_isolated_test_colcon_own)
"""


def folder(build_base: Path) -> Path:
    """Where the two files are, for colcon's build base (``--build-base``, default build)."""
    return Path(os.path.abspath(build_base)) / FOLDER


def cmake_args(build_base: Path, include: Path) -> list[str]:
    """The CMake arguments that put a package under ``include`` through the stable files."""
    return [
        f"-DCMAKE_PROJECT_INCLUDE_BEFORE={folder(build_base) / BEFORE}",
        f"-D{INCLUDE_VARIABLE}={include}",
    ]


def write(build_base: Path) -> Path:
    """Write both files where they differ (never touched otherwise); returns their folder."""
    where = folder(build_base)
    for name, text in ((BEFORE, BEFORE_TEXT), (AFTER, AFTER_TEXT)):
        path = where / name
        data = text.encode()
        try:
            if path.read_bytes() == data:
                continue
        except OSError:
            pass
        write_atomically(path, data)
    return where
