"""Fixtures of the unit tests in more than one folder or module: process trees found again by
a tag (process/, domain_coordinator/), and the environment of the pytest plugin's sessions."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import process_tree
from helpers.process_tree import Launcher
from helpers.pytest_sessions import recording_env, without_resources


@pytest.fixture
def tag() -> Iterator[str]:
    """The test's own tag: its processes, found again by it, are killed at the end."""
    with process_tree.new_tag() as value:
        yield value


@pytest.fixture
def launcher(tag: str) -> Iterator[Launcher]:
    """Starts the test's runners; at the end the tag's processes, then those, are killed."""
    with process_tree.launching(tag) as started:
        yield started


@pytest.fixture
def domain() -> int:
    """A pool of one free ID, so the next run must get the very same ID."""
    return process_tree.one_free_id()


@pytest.fixture
def tree_env(env: dict[str, str], tag: str, domain: int) -> dict[str, str]:
    """The runner environment with the test's tag and its pool of ``domain`` alone."""
    return process_tree.tree_environment(env, tag, domain)


@pytest.fixture
def plain_env(env: dict[str, str], tmp_path: Path) -> dict[str, str]:
    """The runner environment, the recording test writing to ``tmp_path/record.json``."""
    return recording_env(env, tmp_path)


@pytest.fixture
def resource_env(env: dict[str, str], tmp_path: Path) -> dict[str, str]:
    """plain_env without a resource request or capacity of this machine's own."""
    return without_resources(recording_env(env, tmp_path))


@pytest.fixture
def exhausted_env(plain_env: dict[str, str], one_id: dict[str, str]) -> dict[str, str]:
    """plain_env on a pool of one ID, waiting 1 s at most: for the tests of a pool held up."""
    return {**plain_env, **one_id, "ROS_ISOLATED_TEST_WAIT_TIMEOUT": "1"}
