"""Where this installation keeps what CMake and colcon are pointed at.

``runner-path`` and ``cmake-include`` print these paths; CMakeLists.txt files and colcon
defaults files then name them. The answers depend on how the package was installed (pip
into a prefix, an editable install, a checkout), which only this module needs to know.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

#: The CMake file of ``cmake-include``, with the CMake package (pip: <prefix>/share/...).
CMAKE_INCLUDE = Path("share/ros_isolated_test/cmake/ros_isolated_test_project_include.cmake")


def runner_script() -> Path:
    """The ctest RUNNER script (``run_test_isolated.py``), resolved."""
    script = resources.files("ros_isolated_test.ament") / "run_test_isolated.py"
    return Path(str(script)).resolve()


def cmake_include() -> Path | None:
    """Where this installation's CMake include is, or None when it is not installed.

    pip puts share/ beside the lib/ holding the package (a venv, --prefix, --user); an
    editable install or a checkout has only the package's own cmake/ folder. Not resolved:
    a linked share/ (scripts/setup.sh) keeps the prefix whose bin/ the CMake files use.
    """
    package = Path(str(resources.files("ros_isolated_test")))
    candidates = [parent / CMAKE_INCLUDE for parent in package.parents]
    candidates.append(package / "cmake" / CMAKE_INCLUDE.name)
    return next((path.absolute() for path in candidates if path.is_file()), None)


def colcon_defaults(include: Path) -> str:
    """A colcon defaults file (COLCON_DEFAULTS_FILE) passing ``include`` to every build."""
    argument = json.dumps(f"-DCMAKE_PROJECT_INCLUDE={include}")  # JSON strings are YAML's too
    return (
        "# colcon defaults (COLCON_DEFAULTS_FILE): ros-isolated-test isolates the tests of\n"
        "# every ament_cmake package colcon builds. A --cmake-args given on the command line\n"
        "# replaces this list: name the include there too. To add it to a defaults file\n"
        "# you already have: ros-isolated-test cmake-include --colcon-defaults FILE\n"
        f"build:\n  cmake-args:\n    - {argument}"
    )
