"""One version and one licence in every place the sources name them.

ros_isolated_test/__init__.py holds the version: pyproject.toml reads it from there, and
package.xml (which bloom and colcon read as it is), CHANGELOG.rst's newest entry (which
bloom turns into the Debian changelog) and the CMake package's version file repeat it.
The built artefacts (wheel METADATA, the .deb's control and copyright) are checked in
tests/e2e/test_release.py.
"""

from __future__ import annotations

import importlib
import re
from typing import Any

from catkin_pkg.changelog import get_changelog_from_path  # type: ignore[import-untyped]
from catkin_pkg.package import parse_package  # type: ignore[import-untyped]
from helpers import capabilities
from helpers.commands import REPO

import ros_isolated_test

VERSION = ros_isolated_test.__version__
LICENSE = "Apache-2.0"


def _pyproject() -> dict[str, Any]:
    tomllib = importlib.import_module("tomllib")  # 3.11+; the suite also runs on 3.10
    data: dict[str, Any] = tomllib.loads((REPO / "pyproject.toml").read_text())
    return data


def test_the_version_is_a_release_version() -> None:
    assert re.fullmatch(r"\d+\.\d+\.\d+", VERSION), VERSION


@capabilities.TOMLLIB
def test_pyproject_reads_the_version_from_the_package() -> None:
    config = _pyproject()
    assert "version" not in config["project"]
    assert "version" in config["project"]["dynamic"]
    attr = config["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "ros_isolated_test.__version__"


def test_package_xml_and_the_cmake_package_repeat_it() -> None:
    assert parse_package(str(REPO)).version == VERSION
    cmake = REPO / "ros_isolated_test" / "cmake" / "ros_isolated_testConfigVersion.cmake"
    assert f'set(PACKAGE_VERSION "{VERSION}")' in cmake.read_text()


def test_the_changelog_is_in_catkins_format_and_its_newest_entry_is_this_version() -> None:
    """What bloom reads (catkin_pkg's parser): a dated entry for every released version."""
    changelog = get_changelog_from_path(str(REPO / "CHANGELOG.rst"), "ros_isolated_test")
    assert changelog is not None
    entries = list(changelog.foreach_version())
    assert entries, "CHANGELOG.rst holds no version entry"
    version, date, content = entries[0]
    assert version == VERSION
    assert date is not None
    assert str(content).strip()
    # catkin_generate_changelog's title, which bloom and catkin_test_changelog expect.
    lines = (REPO / "CHANGELOG.rst").read_text().splitlines()
    assert lines[1] == "Changelog for package ros_isolated_test"
    assert lines[0] == lines[2] == "^" * len(lines[1])


@capabilities.TOMLLIB
def test_the_licence_agrees_and_its_text_is_the_whole_apache_2_0() -> None:
    manifest = parse_package(str(REPO))
    assert [str(license_) for license_ in manifest.licenses] == [LICENSE]
    assert [license_.file for license_ in manifest.licenses] == ["LICENSE"]
    assert _pyproject()["project"]["license"] == {"text": LICENSE}
    text = " ".join((REPO / "LICENSE").read_text().split())
    assert text.startswith("Apache License Version 2.0, January 2004"), text[:80]
    for section in range(1, 10):  # the nine sections of the terms, none left out
        assert f" {section}. " in text, section
    assert "END OF TERMS AND CONDITIONS" in text
    assert "APPENDIX: How to apply the Apache License to your work." in text
