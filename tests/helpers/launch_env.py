"""A virtualenv for the launch tier: real launch_testing and launch_pytest beside ROS 2 Jazzy.

launch_testing and launch_pytest are in no registry, so they come from the vendored Jazzy
sources in the outside tier (``../shared``), and their pytest plugins break pytest 9,
which the suite's own ``.venv`` has (launch_pytest breaks on pytest 8 already): so they
live in an environment of their own, never in ``.venv``, where both plugins are loaded by
every pytest run, as on a ROS machine. It holds the ros extra (read from pyproject.toml,
so the two never drift), ``pytest<8`` (Jazzy's) and pytest-xdist, the vendored
``launch`` packages (``--no-deps``: their metadata names packages PyPI spells otherwise),
``launch_testing_ament_cmake`` installed by CMake into its prefix, and this project as
an editable install of the checkout. An editable install copies no data files, so the
CMake package is linked in by hand where pip would put it (``share/ros_isolated_test/cmake``
beside ``bin/ros-isolated-test``): the launch tier finds it in its own prefix, never
through another environment's.

It is built once and kept in ``.venv-launch/`` (git-ignored), keyed by a hash of
everything it is made of; a change to any of those builds it again. A lock keeps two
sessions from building it at once.
"""

from __future__ import annotations

import fcntl
import hashlib
import importlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from helpers.capabilities import LAUNCH_SOURCES
from helpers.commands import REPO

#: Where the environment is kept between sessions (git-ignored).
HOME = REPO / ".venv-launch"
PREFIX = HOME / "env"
PYTHON = PREFIX / "bin" / "python"
#: Where pip would install the CMake package, and what is linked there instead.
CMAKE_PACKAGE = PREFIX / "share" / "ros_isolated_test" / "cmake"
CMAKE_FILES = REPO / "ros_isolated_test" / "cmake"
#: The vendored Python packages, in dependency order.
PYTHON_PACKAGES = ("launch", "launch_xml", "launch_yaml", "launch_testing", "launch_pytest")
#: What the vendored packages need from PyPI (their setup.py names them otherwise or not).
LAUNCH_DEPENDENCIES = (
    "osrf-pycommon",
    "lark",
    "pyyaml",
    "ros-jazzy-ament-index-python",
    # launch_testing_ament_cmake's CMake config finds PythonExtra through it.
    "ros-jazzy-python-cmake-module",
)
#: What ROS 2 Jazzy runs on Ubuntu 24.04 (pytest 7.4): launch_testing's pytest11 plugin uses
#: a hook argument pytest 9 removed; launch_pytest reads ``_pytestfixturefunction``, which
#: 8.4's fixtures no longer have, and a generator test of a module-scoped launch calls
#: ``getfixtureinfo(funcargs=...)``, which pytest 8 removed (a TypeError on 8.0 to 8.3).
PYTEST = "pytest<8"
#: Launch files under pytest-xdist (tests/unit/pytest_plugin/): their cases on one worker.
XDIST = "pytest-xdist"


class LaunchEnvError(RuntimeError):
    """A step of building the environment failed: a product or setup error, never a skip."""


def ros_requirements() -> list[str]:
    """The ros extra of pyproject.toml, the same ROS 2 as the suite's own ``.venv``."""
    tomllib = importlib.import_module("tomllib")  # 3.11+, as the ROS 2 Jazzy wheels are
    data = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    ros: list[str] = data["project"]["optional-dependencies"]["ros"]
    return ros


def _fingerprint() -> str:
    """A hash of what the environment is made of: any change means a rebuild."""
    digest = hashlib.sha256()
    digest.update(sys.version.encode())
    digest.update("\n".join([*ros_requirements(), *LAUNCH_DEPENDENCIES, PYTEST, XDIST]).encode())
    digest.update(Path(__file__).read_bytes())
    for name in (*PYTHON_PACKAGES, "launch_testing_ament_cmake"):
        for path in sorted((LAUNCH_SOURCES / name).rglob("*")):
            if path.is_file():
                digest.update(str(path.relative_to(LAUNCH_SOURCES)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _run(command: list[str], log: Path, **kwargs: object) -> None:
    """Run one build step, its output appended to ``log``; fail with the log's tail."""
    with log.open("a") as out:
        out.write(f"$ {' '.join(command)}\n")
        out.flush()
        done = subprocess.run(  # type: ignore[call-overload]
            command, stdout=out, stderr=subprocess.STDOUT, check=False, **kwargs
        )
    if done.returncode != 0:
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-40:])
        raise LaunchEnvError(f"{' '.join(command)} exited {done.returncode}:\n{tail}")


def _build(log: Path) -> None:
    """Make the environment from nothing in PREFIX."""
    shutil.rmtree(PREFIX, ignore_errors=True)
    _run([sys.executable, "-m", "venv", str(PREFIX)], log)
    pip = [str(PYTHON), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    _run([*pip, "--upgrade", "pip"], log)
    _run([*pip, *ros_requirements(), *LAUNCH_DEPENDENCIES, PYTEST, XDIST], log)
    # pip builds the legacy setup.py packages in their own folder: build copies, so the
    # shared sources are never written to.
    with tempfile.TemporaryDirectory(prefix="launch-sources-") as scratch:
        copies = [shutil.copytree(LAUNCH_SOURCES / name, Path(scratch) / name) for name in
                  PYTHON_PACKAGES]  # fmt: skip
        _run([*pip, "--no-deps", *map(str, copies)], log)
        env = {**os.environ, "PATH": f"{PREFIX / 'bin'}{os.pathsep}{os.environ['PATH']}"}
        build = Path(scratch) / "build-launch_testing_ament_cmake"
        _run(
            ["cmake", "-S", str(LAUNCH_SOURCES / "launch_testing_ament_cmake"), "-B",
             str(build), f"-DCMAKE_INSTALL_PREFIX={PREFIX}", f"-DCMAKE_PREFIX_PATH={PREFIX}",
             f"-DPython3_EXECUTABLE={PYTHON}", "-DBUILD_TESTING=OFF"],
            log, env=env,
        )  # fmt: skip
        _run(["cmake", "--install", str(build)], log, env=env)
    _run([*pip, "-e", str(REPO)], log)  # its dependencies; ensure() installs it again later


def _project_fingerprint() -> str:
    """A hash of what the editable install registers (entry points, dependencies)."""
    return hashlib.sha256((REPO / "pyproject.toml").read_bytes()).hexdigest()[:16]


def _link_cmake_package() -> None:
    """``share/ros_isolated_test/cmake`` in PREFIX: the checkout's files, live."""
    link = CMAKE_PACKAGE
    link.parent.mkdir(parents=True, exist_ok=True)
    if link.is_symlink() and link.resolve() == CMAKE_FILES.resolve():
        return
    if link.is_symlink() or link.is_file():
        link.unlink()
    elif link.is_dir():
        shutil.rmtree(link)
    link.symlink_to(CMAKE_FILES)


def ensure() -> Path:
    """The environment's Python, built now unless a build of the same inputs is there.

    This project is installed again (a few seconds) when only its pyproject.toml changed;
    its Python and CMake files are the checkout's own, through links.
    """
    HOME.mkdir(exist_ok=True)
    built = PREFIX / f".built-{_fingerprint()}"
    installed = PREFIX / f".project-{_project_fingerprint()}"
    with (HOME / "build.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another session building: wait for its result
        log = HOME / "build.log"
        if not built.is_file():
            log.write_text("")
            _build(log)
            built.touch()
        if not installed.is_file():
            pip = [str(PYTHON), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
            _run([*pip, "--no-deps", "-e", str(REPO)], log)
            for stale in PREFIX.glob(".project-*"):
                stale.unlink()
            installed.touch()
        _link_cmake_package()
    return PYTHON
