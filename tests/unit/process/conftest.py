"""Fixtures of the process tests: tags that find a test's processes again, and discovery on
this host only (``tag``, ``launcher``, ``domain`` and ``tree_env`` are tests/unit/conftest.py's,
which test_block.py shares)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from helpers import capabilities
from helpers.survivors import kill_all_with, new_tag


@pytest.fixture
def tags() -> Iterator[Callable[[], str]]:
    """Unique tags (numbers ``sleep`` accepts); all their processes are killed at the end."""
    made: list[str] = []

    def new() -> str:
        made.append(new_tag())
        return made[-1]

    yield new
    for tag in made:
        kill_all_with(tag)


@pytest.fixture
def ros_env(tree_env: dict[str, str]) -> dict[str, str]:
    """Discovery on this host only: nothing from the network can pass for crosstalk."""
    return {**tree_env, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


@pytest.fixture(scope="module")
def pid_namespaces() -> None:
    capabilities.require(capabilities.UNSHARE)
