"""The tests are laid out like the code: unit tests mirror the package, end to end apart.

A newcomer looking for the tests of ``ros_isolated_test/xunit/reader.py`` opens
``tests/unit/xunit/test_reader.py`` (and the ``test_reader_<topic>.py`` files beside
it). Tests that run the tool as its users do, across its parts (ctest, colcon, Docker,
real ROS, the result files' consumers), live in ``tests/e2e/``; checks of the repository
itself (docs, imports, packaging) in ``tests/repo/``. No product module is over 500
lines: past that, a file holds more than its name says. docs/contributing.md's layout
table names every module, so a newcomer finds what each one does.
"""

from __future__ import annotations

from pathlib import Path

from helpers.commands import REPO
from helpers.layout import loose_tests, missing_tests, strays, unnamed_modules

PACKAGE = REPO / "ros_isolated_test"
TESTS = REPO / "tests"
#: The most lines a product module may have.
MODULE_LIMIT = 500


def _plant(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_control_a_planted_gap_a_stray_and_a_loose_test_are_seen(tmp_path: Path) -> None:
    code = "def f() -> None:\n    pass\n"
    _plant(
        tmp_path,
        {
            "pkg/__init__.py": "VERSION = '1'\n",
            "pkg/kept.py": code,
            "pkg/untested.py": code,
            "pkg/constants.py": "LIMIT = 1\n",
            "pkg/sub/__init__.py": code,
            "tests/unit/test_kept.py": "",
            "tests/unit/test_kept_topic.py": "",
            "tests/unit/test_gone.py": "",
            "tests/unit/sub/test_sub.py": "",
            "tests/e2e/test_whole.py": "",
            "tests/test_loose.py": "",
            "tests/data/test_sample.py": "",
        },
    )
    package, tests = tmp_path / "pkg", tmp_path / "tests"
    assert missing_tests(package, tests / "unit") == ["untested.py -> test_untested.py"]
    assert strays(package, tests / "unit") == ["test_gone.py"]
    assert loose_tests(tests) == ["test_loose.py"]


def test_every_source_module_has_its_unit_test_module() -> None:
    assert missing_tests(PACKAGE, TESTS / "unit") == []


def test_every_unit_test_module_is_named_for_a_module_of_the_folder_it_mirrors() -> None:
    assert strays(PACKAGE, TESTS / "unit") == []


def test_every_test_module_is_in_unit_e2e_or_repo() -> None:
    assert loose_tests(TESTS) == []


def test_no_product_module_is_over_500_lines() -> None:
    sizes = {
        str(path.relative_to(REPO)): len(path.read_text(encoding="utf-8").splitlines())
        for path in PACKAGE.rglob("*.py")
    }
    assert {path: lines for path, lines in sizes.items() if lines > MODULE_LIMIT} == {}
    assert max(sizes.values()) > 100  # control: the files were read


def test_the_layout_table_names_every_module() -> None:
    contributing = (REPO / "docs" / "contributing.md").read_text(encoding="utf-8")
    assert unnamed_modules(PACKAGE, contributing) == []


def test_control_a_module_the_table_leaves_out_is_seen(tmp_path: Path) -> None:
    code = "def f() -> None:\n    pass\n"
    _plant(
        tmp_path,
        {
            "pkg/top.py": code,
            "pkg/sub/__init__.py": "",
            "pkg/sub/kept.py": code,
            "pkg/sub/gone.py": code,
            "pkg/sub/deep/leaf.py": code,
        },
    )
    table = (
        "# Contributing\n\n## Layout\n\n| step | where |\n|---|---|\n"
        "| one | `top.py`, `sub/` (`kept`: named by its folder and name) |\n"
        "| two | `sub/deep/leaf.py` |\n\n## Next\n\n| `gone` | elsewhere |\n"
    )
    assert unnamed_modules(tmp_path / "pkg", table) == ["sub/gone.py"]
