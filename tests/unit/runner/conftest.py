"""Fixtures of the runner's tests: a pool of IDs free now, for runs that take more than one."""

from __future__ import annotations

import pytest
from helpers.domains import free_ids


@pytest.fixture
def two_ids(env: dict[str, str]) -> dict[str, str]:
    """The runner environment with a pool of two IDs free now."""
    return {**env, "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, free_ids(2)))}
