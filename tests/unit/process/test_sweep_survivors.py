"""What the sweep cannot end survives the run, is named, and keeps the ID blocked while it lives.

A process that outlives even SIGKILL (one the runner may not signal, one stuck in the
kernel) is reported as a survivor: named in the output and the result file, and written
down in a block record, so no runner, of any user, takes the ID until it is gone. For
real: a setuid-root process the runner, run as nobody, may not signal at all; started
through ``env -i``, so no squatter scan can see it either. The control: once it is gone,
the ID is handed out again.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.commands import run_cli
from helpers.domains import free_ids
from helpers.process_tree import POOL_VAR
from helpers.results import load_result
from helpers.survivors import alive_with, build_setuid_helper, kill_all_with

NOBODY = 65534


@pytest.fixture
def survivor_setup(traversable_dir: Path, env: dict[str, str]) -> tuple[Path, Path, dict[str, str]]:
    """A setuid-root helper, a lock directory nobody can use, and the environment for it."""
    helper = build_setuid_helper(traversable_dir)
    locks = traversable_dir / "locks"
    locks.mkdir()
    os.chmod(locks, 0o1777)
    (domain_id,) = free_ids(1)
    runner_env = {
        **env,
        "ROS_ISOLATED_TEST_LOCK_DIR": str(locks),
        POOL_VAR: str(domain_id),
        "HOME": "/nonexistent",
        "USER": "nobody",
    }
    return helper, locks, runner_env


def test_a_process_the_runner_cannot_end_keeps_the_id_blocked(
    survivor_setup: tuple[Path, Path, dict[str, str]],
    traversable_dir: Path,
    tags: Callable[[], str],
) -> None:
    helper, locks, runner_env = survivor_setup
    domain_id = int(runner_env[POOL_VAR])
    tag = tags()
    result = traversable_dir / "result.xml"
    as_nobody = {"user": NOBODY, "group": NOBODY, "extra_groups": [], "cwd": traversable_dir}
    # Through env -i, as the red team's children: no squatter scan can see it either.
    command = ["env", "-i", str(helper), tag]
    done = run_cli(
        ["run", "--kill-grace", "0.5", "--junit-xml", str(result), "--", *command],
        runner_env,
        **as_nobody,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (survivor,) = alive_with(tag)
    # Root for real: the runner's user may not signal it. No ROS_DOMAIN_ID to see.
    assert os.stat(f"/proc/{survivor}").st_uid == 0
    assert b"ROS_DOMAIN_ID" not in Path(f"/proc/{survivor}/environ").read_bytes()
    name = f"{survivor} (setuid_helper)"
    # Named in the output and the result file ...
    assert f"process {name} of the test could not be ended" in done.stdout, done.stdout
    assert f"ROS_DOMAIN_ID {domain_id} stays blocked while {name} live" in done.stdout
    assert load_result(result).properties["surviving_processes"] == name
    assert name not in load_result(result).properties.get("leftover_processes", "")

    # ... and the ID stays blocked after the runner exited, for every user: here root.
    refused = run_cli(["run", "--wait-timeout", "0", "--", "true"], runner_env, cwd=traversable_dir)
    assert refused.returncode == 3, refused.stdout + refused.stderr
    assert f"{domain_id}: survivor pid {survivor}" in refused.stdout + refused.stderr
    listed = run_cli(["status", "--json"], runner_env)
    assert listed.returncode == 0, listed.stderr
    rows = [row for row in json.loads(listed.stdout) if row["via"] == "survivor"]
    assert [(row["domain_id"], row["pid"], row["user"]) for row in rows] == [
        (domain_id, survivor, "root")
    ]
    text = run_cli(["status"], runner_env)
    assert any(
        line.split()[:3] == [str(domain_id), "survivor", str(survivor)]
        for line in text.stdout.splitlines()
    ), text.stdout

    # The control: once the survivor is gone, the ID is handed out again.
    kill_all_with(tag)
    again = run_cli(["run", "--wait-timeout", "0", "--", "true"], runner_env, cwd=traversable_dir)
    assert again.returncode == 0, again.stdout + again.stderr
    assert f"Running with ROS_DOMAIN_ID {domain_id}" in again.stdout
    # Root wrote nothing of nobody's: the stale record and the marker stay, ignored.
    left = sorted(entry for entry in os.listdir(locks) if entry.endswith(".blocked"))
    assert [(locks / entry).stat().st_uid for entry in left] == [NOBODY, NOBODY], left
    assert left[0] == f"domain-{domain_id}.blocked"
