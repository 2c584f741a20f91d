"""Fixtures of the report's unit tests: a colcon build tree of every kind of result file."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.report_text import Tree, build_tree


@pytest.fixture
def tree(env: dict[str, str], tmp_path: Path) -> Tree:
    """A colcon build tree: canonical and raw files, a ctest Test.xml, broken and hidden ones."""
    return build_tree(env, tmp_path)
