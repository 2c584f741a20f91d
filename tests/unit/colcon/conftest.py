from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _extension_on(monkeypatch: pytest.MonkeyPatch) -> None:
    """As a user has it: the suite's own default (off, tests/conftest.py) unset."""
    monkeypatch.delenv("ROS_ISOLATED_TEST_COLCON", raising=False)
