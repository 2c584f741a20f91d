"""The release artefacts as users get them: the wheel and sdist, and the Debian package.

Built once per session from a copy of the checkout (tests/helpers/release.py), each is
checked the way its users meet it: ``twine check`` as PyPI's upload does; the sdist
unpacked alone builds the same wheel; the wheel installed alone into a fresh venv, run
from a folder with no checkout in sight, gives the command, the RUNNER, the CMake include,
``find_package(ros_isolated_test)`` from its prefix and the pytest plugin; the .deb is
built by scripts/package_deb.sh (bloom, then dpkg-buildpackage with its tests), and its
control file, copyright and layout say what package.xml and pyproject.toml say. Installing
the .deb with apt is tests/e2e/test_release_apt.py.

The colcon extension, the fourth way in, is there once colcon is installed beside the
wheel: ``colcon extensions`` of that venv lists it.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tarfile
from email.message import Message
from pathlib import Path

import pytest
from helpers import capabilities, release
from helpers.commands import HUNG, REPO
from helpers.domains import free_ids
from helpers.release import DEB_NAME, ROS_PREFIX, Dists
from helpers.ros_package import copy_checkout

import ros_isolated_test

VERSION = ros_isolated_test.__version__
LICENSE = "Apache-2.0"
PYTHON_DEPENDS = ("python3-click", "python3-filelock", "python3-lxml")
#: What builds the same wheel (package.xml and resource/: setup.py's ament files) and
#: what a packager checks it with.
SDIST_HOLDS = (
    "LICENSE", "CHANGELOG.rst", "README.md", "pyproject.toml", "setup.py", "package.xml",
    "resource/ros_isolated_test", "docs/install.md", "install_check/test_installed.py",
    "tests/conftest.py", "tests/e2e/test_release.py", "scripts/package_deb.sh",
)  # fmt: skip


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The checkout's files, as a fresh clone holds them."""
    return copy_checkout(tmp_path_factory.mktemp("release") / "src")


@pytest.fixture(scope="module")
def dists(source: Path, tmp_path_factory: pytest.TempPathFactory) -> Dists:
    return release.build_dists(source, tmp_path_factory.mktemp("dist"))


@pytest.fixture(scope="module")
def installed(dists: Dists, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv: the wheel (its dependencies from pip), pytest, colcon and its devtools."""
    root = tmp_path_factory.mktemp("venv") / "v"
    return release.fresh_venv(root, str(dists.wheel), "pytest", "colcon-core", "colcon-devtools")


@pytest.fixture(scope="module")
def deb(tmp_path_factory: pytest.TempPathFactory) -> Path:
    capabilities.require(capabilities.DEB_BUILD)
    return release.build_deb(tmp_path_factory.mktemp("deb"))


# -- the wheel and the sdist ------------------------------------------------------------------


@capabilities.RELEASE_TOOLS
def test_twine_check_passes_for_both(dists: Dists) -> None:
    done = subprocess.run(
        ["twine", "check", "--strict", str(dists.sdist), str(dists.wheel)],
        capture_output=True, text=True, timeout=HUNG, check=False,
        env={**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"},
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count("PASSED") == 2, done.stdout


@capabilities.RELEASE_TOOLS
def test_the_sdist_holds_what_a_packager_needs_and_builds_the_same_wheel(
    dists: Dists, tmp_path: Path
) -> None:
    with tarfile.open(dists.sdist) as archive:
        names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    for needed in SDIST_HOLDS:
        assert needed in names, f"{needed} is not in the sdist"
    assert not [name for name in names if "__pycache__" in name]
    rebuilt = release.wheel_from_sdist(dists.sdist, tmp_path)
    assert rebuilt.name == dists.wheel.name
    assert release.wheel_contents(rebuilt) == release.wheel_contents(dists.wheel)


def _in_fresh_venv(
    venv: Path, cwd: Path, *command: str, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """A command as a user of that venv runs it: its bin/ first on PATH, no PYTHONPATH."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    clean = {k: v for k, v in clean.items() if not k.startswith(("ROS_", "AMENT_", "CMAKE_"))}
    clean["PATH"] = f"{venv / 'bin'}:/usr/bin:/bin"
    return subprocess.run(
        list(command), cwd=cwd, env={**clean, **(env or {})}, capture_output=True, text=True,
        timeout=HUNG, check=False,
    )  # fmt: skip


@capabilities.RELEASE_TOOLS
@capabilities.CTEST
def test_the_wheel_alone_in_a_fresh_venv_gives_every_way_in(
    installed: Path, tmp_path: Path
) -> None:
    site = next((installed / "lib").glob("python3*/site-packages"))
    package = site / "ros_isolated_test"
    command = str(installed / "bin" / "ros-isolated-test")

    shown = _in_fresh_venv(installed, tmp_path, command, "--version")
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.splitlines()[:2] == [
        f"ros-isolated-test {VERSION}",
        f"installed in {package}",
    ], shown.stdout
    assert f"({installed / 'bin' / 'python'})" in shown.stdout.splitlines()[2], shown.stdout

    (pool_id,) = free_ids(1)
    locks = {"ROS_ISOLATED_TEST_LOCK_DIR": str(tmp_path / "locks"),
             "ROS_ISOLATED_TEST_DOMAINS": str(pool_id)}  # fmt: skip
    ran = _in_fresh_venv(
        installed, tmp_path, command, "run", "--", "sh", "-c", 'echo "on $ROS_DOMAIN_ID"', env=locks
    )
    assert ran.returncode == 0, ran.stderr
    assert f"on {pool_id}" in ran.stdout.splitlines(), ran.stdout

    runner = _in_fresh_venv(installed, tmp_path, command, "runner-path").stdout.strip()
    assert Path(runner) == package / "ament" / "run_test_isolated.py"
    include = _in_fresh_venv(installed, tmp_path, command, "cmake-include").stdout.strip()
    assert Path(include).is_file() and Path(include).is_relative_to(installed), include

    project = tmp_path / "cmake"
    project.mkdir()
    (project / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.20)\nproject(tiny NONE)\n"
        f"find_package(ros_isolated_test {VERSION} REQUIRED)\n"
        'message(STATUS "runner=${ros_isolated_test_RUNNER}")\n'
    )
    configured = _in_fresh_venv(
        installed, tmp_path, "cmake", "-S", str(project), "-B", str(tmp_path / "build"),
        f"-DCMAKE_PREFIX_PATH={installed}",
    )  # fmt: skip
    assert configured.returncode == 0, configured.stdout + configured.stderr
    assert f"runner={runner}" in configured.stdout, configured.stdout
    cache = (tmp_path / "build" / "CMakeCache.txt").read_text()
    assert f"ros_isolated_test_DIR:PATH={installed}/share/ros_isolated_test/cmake" in cache

    (tmp_path / "test_domain.py").write_text(
        f"import os\n\ndef test_domain():\n    assert os.environ['ROS_DOMAIN_ID'] == '{pool_id}'\n"
    )
    tested = _in_fresh_venv(
        installed, tmp_path, "python", "-m", "pytest", "-p", "no:cacheprovider",
        "--ros-isolation", "test_domain.py", env=locks,
    )  # fmt: skip
    assert tested.returncode == 0, tested.stdout + tested.stderr
    assert f"ros-isolated-test: ROS_DOMAIN_ID {pool_id}" in tested.stdout, tested.stdout
    # The control: the plugin turned off, the same test finds no ID.
    plain = _in_fresh_venv(
        installed, tmp_path, "python", "-m", "pytest", "-p", "no:cacheprovider",
        "-p", "no:ros_isolated_test", "test_domain.py", env=locks,
    )  # fmt: skip
    assert plain.returncode == 1, plain.stdout + plain.stderr
    assert "KeyError: 'ROS_DOMAIN_ID'" in plain.stdout, plain.stdout

    # colcon of that venv loads the extension: both its extensions listed (the variable's
    # entry point is listed by colcon --help, not here).
    assert _colcon_extensions_of_ours(installed, tmp_path) == EXTENSION_POINTS
    # The control: blocked as docs/install.md says, colcon lists none of them.
    blocked = ":".join(f"{point}.ros_isolated_test" for point in EXTENSION_POINTS)
    assert not _colcon_extensions_of_ours(
        installed, tmp_path, {"COLCON_EXTENSION_BLOCKLIST": blocked}
    )


#: The colcon extension points ``colcon extensions`` lists the colcon extension under.
EXTENSION_POINTS = ["colcon_core.argument_parser", "colcon_core.event_handler"]


def _colcon_extensions_of_ours(
    venv: Path, cwd: Path, env: dict[str, str] | None = None
) -> list[str]:
    """The extension points under which ``colcon extensions`` lists ``ros_isolated_test``."""
    home = {"HOME": str(cwd), **(env or {})}
    listed = _in_fresh_venv(venv, cwd, "colcon", "extensions", env=home)
    assert listed.returncode == 0, listed.stdout + listed.stderr
    points, point = [], ""
    for line in listed.stdout.splitlines():
        if line and not line.startswith(" "):
            point = line.rstrip(":").strip()
        elif line.strip().startswith("ros_isolated_test:"):
            points.append(point)
    return sorted(points)


# -- the Debian package -----------------------------------------------------------------------


@capabilities.DEB_BUILD
def test_the_deb_is_named_as_the_farm_names_it_and_depends_on_apts_python(deb: Path) -> None:
    assert re.fullmatch(rf"{DEB_NAME}_{re.escape(VERSION)}-0noble_all\.deb", deb.name), deb.name
    control = release.deb_control(deb)
    depends = [entry.strip() for entry in control["Depends"].split(",")]
    assert [d for d in depends if d in PYTHON_DEPENDS] == list(PYTHON_DEPENDS), depends
    # What the farm's bloom-release adds to every ROS 2 package; a standalone bloom leaves it out.
    assert "ros-jazzy-ros-workspace" in depends, depends
    shown = subprocess.run(
        ["dpkg-deb", "-I", str(deb)], capture_output=True, text=True, timeout=HUNG, check=True
    )
    assert all(name in shown.stdout for name in PYTHON_DEPENDS), shown.stdout


@capabilities.DEB_BUILD
def test_a_package_whose_tests_fail_is_not_built(deb: Path, tmp_path: Path) -> None:
    """dh_auto_test is not ignored (bloom's rules ignore it): a copy whose built package
    cannot run stops the build. The control is ``deb``, built from the same files intact."""
    source = copy_checkout(tmp_path / "broken")
    main = source / "ros_isolated_test" / "__main__.py"
    main.write_text('raise SystemExit("broken on purpose")\n' + main.read_text())
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    done = subprocess.run(
        [str(source / "scripts" / "package_deb.sh"), str(tmp_path / "out")], env=env,
        capture_output=True, text=True, timeout=release.BUILD_LIMIT_S, check=False,
    )  # fmt: skip
    assert done.returncode != 0, done.stdout
    assert "broken on purpose" in done.stderr, done.stderr
    assert "dh_auto_test: error" in done.stderr, done.stderr
    assert not list((tmp_path / "out").glob("*.deb"))


@capabilities.DEB_BUILD
def test_the_deb_installs_under_opt_ros_jazzy_with_the_package_files(deb: Path) -> None:
    listed = subprocess.run(
        ["dpkg-deb", "-c", str(deb)], capture_output=True, text=True, timeout=HUNG, check=True
    )
    files = [line.split()[-1].lstrip(".") for line in listed.stdout.splitlines()]
    outside = [f for f in files if not f.startswith((f"{ROS_PREFIX}/", "/usr/share/doc/"))]
    # Beside the docs, dh_python3's hook that compiles the bytecode again for a new Python.
    rtupdate = f"/usr/share/python3/runtime.d/{DEB_NAME}.rtupdate"
    assert [f for f in outside if not f.endswith("/")] == [rtupdate], outside
    for installed in (
        f"{ROS_PREFIX}/bin/ros-isolated-test",
        f"{ROS_PREFIX}/share/ros_isolated_test/package.xml",
        f"{ROS_PREFIX}/share/ros_isolated_test/cmake/ros_isolated_testConfig.cmake",
        f"{ROS_PREFIX}/share/ament_index/resource_index/packages/ros_isolated_test",
    ):
        assert installed in files, installed


# -- one version, one licence, everywhere -----------------------------------------------------


def _license_text(copyright_file: str) -> str:
    """The licence text of a Debian copyright file's License paragraph, as plain text."""
    paragraph = copyright_file.split("\nLicense: ", 1)[1].split("\n", 1)[1]
    lines = [line[1:] for line in paragraph.splitlines() if line.startswith(" ")]
    return "\n".join("" if line == "." else line for line in lines)


@capabilities.RELEASE_TOOLS
@capabilities.DEB_BUILD
def test_version_and_licence_agree_across_every_artefact(dists: Dists, deb: Path) -> None:
    from catkin_pkg.package import parse_package  # type: ignore[import-untyped]

    manifest = parse_package(str(REPO))
    metadata: Message = release.wheel_metadata(dists.wheel)
    control = release.deb_control(deb)
    assert manifest.version == VERSION
    assert metadata["Version"] == VERSION
    assert control["Version"].split("-", 1)[0] == VERSION
    assert dists.sdist.name == f"ros_isolated_test-{VERSION}.tar.gz"

    assert [str(license_) for license_ in manifest.licenses] == [LICENSE]
    assert metadata["License"] == LICENSE
    assert metadata.get_all("License-File") == ["LICENSE"]
    shipped = release.wheel_contents(dists.wheel)
    license_text = (REPO / "LICENSE").read_text()
    assert shipped[f"ros_isolated_test-{VERSION}.dist-info/licenses/LICENSE"].decode() == (
        license_text
    )
    copyright_file = release.deb_file(deb, f"/usr/share/doc/{DEB_NAME}/copyright")
    assert f"\nLicense: {LICENSE}\n" in copyright_file, copyright_file
    assert _license_text(copyright_file).strip() == license_text.strip()
