"""package.xml and setup.py as colcon, rosdep and bloom read them, against pyproject.toml.

catkin_pkg is what colcon, rosdep and bloom parse a package.xml with (and what rejects one
bloom would refuse); colcon's ament_python build reads setup.py through
colcon-python-setup-py with the environment's own setuptools. The end-to-end build on
Ubuntu 24.04's versions is tests/e2e/test_ros_package.py.
"""

from __future__ import annotations

import importlib
import re
import shutil
from pathlib import Path
from typing import Any

import pytest
from catkin_pkg.package import Package, parse_package  # type: ignore[import-untyped]
from catkin_pkg.packages import find_packages  # type: ignore[import-untyped]
from helpers import capabilities
from helpers.commands import REPO
from helpers.ros_package import PACKAGE, ubuntu_versions
from packaging.requirements import Requirement

import ros_isolated_test

#: REP 144: a package name is lower case letters, digits and underscores, a letter first.
REP_144 = re.compile(r"^[a-z][a-z0-9_]*$")


def _pyproject() -> dict[str, Any]:
    tomllib = importlib.import_module("tomllib")  # 3.11+; the suite also runs on 3.10
    data: dict[str, Any] = tomllib.loads((REPO / "pyproject.toml").read_text())
    return data


@pytest.fixture(scope="module")
def manifest() -> Package:
    warnings: list[str] = []
    package = parse_package(str(REPO), warnings=warnings)
    assert warnings == [], warnings
    return package


def _rosdep_key(requirement: str) -> str:
    """The rosdep key of a PyPI requirement: Ubuntu's and rosdep's ``python3-<name>``."""
    return f"python3-{Requirement(requirement).name.lower()}"


@capabilities.TOMLLIB
def test_package_xml_is_a_format_3_ament_python_package_bloom_accepts(manifest: Package) -> None:
    manifest.validate()  # what bloom runs before it releases: raises on anything invalid
    assert manifest.package_format == 3
    assert manifest.name == PACKAGE
    assert REP_144.match(manifest.name)
    assert manifest.get_build_type() == "ament_python"
    assert manifest.licenses == ["Apache-2.0"]
    assert all(person.email for person in manifest.maintainers)


def test_its_version_is_the_packages(manifest: Package) -> None:
    """The one version (ros_isolated_test/__init__.py); the rest: tests/repo/test_metadata.py."""
    assert manifest.version == ros_isolated_test.__version__


@capabilities.TOMLLIB
def test_its_dependencies_are_pyprojects_as_rosdep_keys(manifest: Package) -> None:
    required = _pyproject()["project"]["dependencies"]
    assert sorted(d.name for d in manifest.exec_depends) == sorted(map(_rosdep_key, required))
    assert sorted(d.name for d in manifest.run_depends) == sorted(map(_rosdep_key, required))
    # Nothing else is needed to build it; its tests (the Debian build's dh_auto_test, which
    # runs the built package) need what it runs on.
    assert manifest.build_depends == []
    assert sorted(d.name for d in manifest.test_depends) == sorted(map(_rosdep_key, required))


@capabilities.TOMLLIB
def test_pips_floors_admit_what_ubuntu_2404_ships() -> None:
    """apt's click, filelock and lxml satisfy the project; apt's setuptools builds it."""
    pins = ubuntu_versions()
    project = _pyproject()
    for requirement in map(Requirement, project["project"]["dependencies"]):
        assert requirement.specifier.contains(pins[requirement.name]), requirement
    for requirement in map(Requirement, project["build-system"]["requires"]):
        assert requirement.specifier.contains(pins[requirement.name]), requirement


def test_catkin_pkg_finds_the_repository_as_one_package() -> None:
    """rosdep and bloom crawl with catkin_pkg: they see one package, never the examples."""
    found = find_packages(str(REPO))
    assert [(path, package.name) for path, package in found.items()] == [(".", PACKAGE)]
    assert find_packages(str(REPO / "examples")) == {}  # COLCON_IGNORE
    # The control: a crawl that starts inside an example does find it.
    inside = find_packages(str(REPO / "examples" / "crosstalk_demo"))
    assert [package.name for package in inside.values()] == ["crosstalk_demo"]


def _setup_information(folder: Path) -> dict[str, Any]:
    """What colcon's ament_python build reads from ``folder/setup.py`` (this setuptools)."""
    module = importlib.import_module(
        "colcon_python_setup_py.package_identification.python_setup_py"
    )
    information: dict[str, Any] = module.get_setup_information(folder / "setup.py")
    return information


@capabilities.COLCON
def test_colcon_reads_setup_py_with_the_ament_files_and_literal_metadata() -> None:
    information = _setup_information(REPO)
    data_files = dict(information["data_files"])
    assert data_files["share/ament_index/resource_index/packages"] == [f"resource/{PACKAGE}"]
    assert data_files[f"share/{PACKAGE}"] == ["package.xml"]
    assert data_files[f"share/{PACKAGE}/cmake"]  # pyproject.toml's, kept
    assert (REPO / "resource" / PACKAGE).is_file()
    assert information["metadata"]["python_requires"] == _pyproject()["project"]["requires-python"]


@capabilities.COLCON
def test_a_bare_setup_py_stops_colcons_reading(tmp_path: Path) -> None:
    """The control (colcon-core#584): pyproject.toml's requires-python is no literal."""
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, tmp_path / name)
    (tmp_path / "setup.py").write_text("from setuptools import setup\n\nsetup()\n")
    with pytest.raises(SyntaxError):
        _setup_information(tmp_path)
