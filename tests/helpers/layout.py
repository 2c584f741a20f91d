"""Where each test lives: the unit tests mirror the package, everything else has a folder.

``tests/unit/<path>/test_<module>.py`` holds the tests of ``<package>/<path>/<module>.py``;
a module whose tests are long may add topic files beside it, named
``test_<module>_<topic>.py``. A package's ``__init__.py`` that defines code is tested by
``test_<package>.py`` in its folder. Modules with no function or class (a version, a
``__main__`` that calls the CLI) need no test module of their own.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

#: The folders beside ``unit/`` that hold test modules; nothing else in tests/ does.
OTHER_FOLDERS = ("e2e", "repo")


def _defines_code(path: Path) -> bool:
    """Whether a module defines a function or a class (else there is nothing to test)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    kinds = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)
    return any(isinstance(node, kinds) for node in tree.body)


def expected_tests(package_dir: Path) -> dict[str, Path]:
    """Each source module (relative path) -> its test module, relative to ``tests/unit``."""
    expected: dict[str, Path] = {}
    for path in sorted(package_dir.rglob("*.py")):
        if "__pycache__" in path.parts or not _defines_code(path):
            continue
        relative = path.relative_to(package_dir)
        folder = relative.parent
        if path.name == "__init__.py":
            if folder == Path():
                continue  # the package's own version and docstring
            name = folder.name
        else:
            name = path.stem
        expected[str(relative)] = folder / f"test_{name}.py"
    return expected


def missing_tests(package_dir: Path, unit_dir: Path) -> list[str]:
    """Source modules without their test module: ``source -> expected test``."""
    return [
        f"{source} -> {test}"
        for source, test in expected_tests(package_dir).items()
        if not (unit_dir / test).is_file()
    ]


def strays(package_dir: Path, unit_dir: Path) -> list[str]:
    """Unit test modules named for no module of the folder they mirror."""
    names: dict[Path, set[str]] = {}
    for test in expected_tests(package_dir).values():
        names.setdefault(test.parent, set()).add(test.stem)
    found = []
    for path in sorted(unit_dir.rglob("test_*.py")):
        relative = path.relative_to(unit_dir)
        stems = names.get(relative.parent, set())
        if not any(path.stem == stem or path.stem.startswith(f"{stem}_") for stem in stems):
            found.append(str(relative))
    return found


def loose_tests(tests_dir: Path) -> list[str]:
    """Test modules outside ``unit/`` and the other named folders."""
    homes = [tests_dir / "unit", *(tests_dir / name for name in OTHER_FOLDERS)]
    return [
        str(path.relative_to(tests_dir))
        for path in sorted(tests_dir.rglob("test_*.py"))
        if not any(home in path.parents for home in homes)
        and "data" not in path.relative_to(tests_dir).parts
    ]


def _layout_rows(contributing: str) -> list[str]:
    """The rows of the layout table: docs/contributing.md's "## Layout" section."""
    section = contributing.split("\n## Layout\n", 1)[1].split("\n## ", 1)[0]
    return [line for line in section.splitlines() if line.startswith("| ")]


def _named_in(row: str, module: Path) -> bool:
    """Whether ``row`` names ``module`` (relative to the package): its path, or its folder
    and its name (``report/`` (`tree`, ...) names ``report/tree.py``).
    """
    full = module.as_posix()
    if f"`{full}`" in row or f"/{full}`" in row:
        return True
    stem = re.escape(module.stem)
    if not re.search(rf"`{stem}(\.py)?`", row):
        return False
    folder = module.parent.as_posix()
    return folder == "." or bool(re.search(rf"`(ros_isolated_test/)?{re.escape(folder)}/", row))


def unnamed_modules(package_dir: Path, contributing: str) -> list[str]:
    """The package's modules the layout table names nowhere (an ``__init__`` with no code,
    a docstring and imports only, needs no row).
    """
    rows = _layout_rows(contributing)
    found = []
    for path in sorted(package_dir.rglob("*.py")):
        if "__pycache__" in path.parts or (path.name == "__init__.py" and not _defines_code(path)):
            continue
        module = path.relative_to(package_dir)
        if not any(_named_in(row, module) for row in rows):
            found.append(module.as_posix())
    return found
