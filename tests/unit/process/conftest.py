"""Fixtures of the process tests: tags that find a test's processes again, runners in the
background, and a pool of one free ID so the next run must get the very same ID."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from helpers import capabilities, process_tree
from helpers.process_tree import Launcher
from helpers.survivors import kill_all_with, new_tag


@pytest.fixture
def tag() -> Iterator[str]:
    with process_tree.new_tag() as value:
        yield value


@pytest.fixture
def launcher(tag: str) -> Iterator[Launcher]:
    with process_tree.launching(tag) as started:
        yield started


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
def domain() -> int:
    return process_tree.one_free_id()


@pytest.fixture
def tree_env(env: dict[str, str], tag: str, domain: int) -> dict[str, str]:
    return process_tree.tree_environment(env, tag, domain)


@pytest.fixture
def ros_env(tree_env: dict[str, str]) -> dict[str, str]:
    """Discovery on this host only: nothing from the network can pass for crosstalk."""
    return {**tree_env, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


@pytest.fixture(scope="module")
def pid_namespaces() -> None:
    capabilities.require(capabilities.UNSHARE)
