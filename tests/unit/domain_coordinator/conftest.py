"""Fixtures of the domain coordinator's tests in more than one module: a lock directory
shared by all users (test_lock_dir_unusable.py, test_reservation_hostile.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.hostile_lock_dir import make_shared_lock_dir


@pytest.fixture
def shared_lock_dir(traversable_dir: Path) -> Path:
    """A mode-1777 lock directory that the users nobody and daemon can reach."""
    return make_shared_lock_dir(traversable_dir)
