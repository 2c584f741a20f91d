"""``cli.status``: ``status`` over a fresh lock directory (the table: its own test)."""

from __future__ import annotations

import os
from pathlib import Path

from helpers.commands import run_cli


def test_status_lists_nothing_in_a_fresh_lock_dir(env: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(["status", "--json"], env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert '"via": "lock"' not in proc.stdout
    assert os.listdir(env["ROS_ISOLATED_TEST_LOCK_DIR"]) == []
