"""Planting things in the shared lock directory, and proving the runner left them alone.

Anyone may create entries in a mode-1777 directory, at any name a runner uses. The tests
of a hostile lock directory plant files, links, FIFOs and folders there (owned by other
users when we are root), run the real runner with a timeout that tells a hang from a
refusal, and compare snapshots taken without following any link: what the runner must
never have written, replaced or reached through a link.
"""

from __future__ import annotations

import os
import random
import shlex
import stat
import subprocess
from pathlib import Path

import pytest

from helpers.commands import CLI, HUNG, the_error_line
from helpers.coordinator import ids_seen
from helpers.domains import HIGH_IDS, free_ids
from helpers.processes import user_keywords
from ros_isolated_test.domain_coordinator import LOCK_DIR_ENV, POOL_ENV

NOBODY, DAEMON = 65534, 1
#: A run that takes longer than this is hanging (on a FIFO, a lock, a mount): the suite's
#: hang stopper, never a bound a loaded machine can reach on a run that ends.
HANG = HUNG
#: Long ago, so that any touch by the runner shows.
OLD_MTIME_NS = 978_307_200 * 10**9


def pick_ids(count: int) -> list[int]:
    """Free IDs in random order: other test runs on this machine start at the lowest."""
    return free_ids(count, random.sample(HIGH_IDS, len(HIGH_IDS)))


def snapshot(path: Path) -> tuple[object, ...]:
    """Everything the runner could change about an entry without following it."""
    info = os.lstat(path)
    content: object = None
    if stat.S_ISREG(info.st_mode):
        content = path.read_bytes()
    elif stat.S_ISLNK(info.st_mode):
        content = os.readlink(path)
    return (info.st_mode, info.st_uid, info.st_gid, info.st_ino, info.st_mtime_ns, content)


def tree(root: Path) -> dict[str, tuple[object, ...]]:
    """Snapshots of every entry under ``root`` (itself excluded), links not followed."""
    found: dict[str, tuple[object, ...]] = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder, name)
            found[str(path.relative_to(root))] = snapshot(path)
    return found


def assert_unchanged(path: Path, before: tuple[object, ...]) -> None:
    assert os.path.lexists(path), f"{path} was removed or replaced by the runner"
    assert snapshot(path) == before, f"{path} was changed by the runner"


def plant_file(path: Path, owner: int, mode: int, content: bytes = b"planted\n") -> None:
    """Owned by ``owner`` when we are root; otherwise by us (the tests that need it skip)."""
    path.write_bytes(content)
    if os.getuid() == 0:
        os.chown(path, owner, owner)
    os.chmod(path, mode)
    os.utime(path, ns=(OLD_MTIME_NS, OLD_MTIME_NS))


def run_timed(
    args: list[str], env: dict[str, str], timeout: float = HANG, **kwargs: object
) -> subprocess.CompletedProcess[str]:
    """``ros-isolated-test ARGS``; a run that outlives ``timeout`` fails the test as a hang."""
    try:
        return subprocess.run(  # type: ignore[call-overload, no-any-return]
            [CLI, *args],
            check=False,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            **kwargs,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"ros-isolated-test {shlex.join(args)} hung: killed after {timeout} s")


def as_user(uid: int, args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return run_timed(args, env, **user_keywords(uid))


def granted_id(result: subprocess.CompletedProcess[str]) -> int:
    """The ID the test command saw, from its ``id=`` line; fails with the run's output."""
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    (seen,) = ids_seen(result.stdout)
    return seen


def error_line(result: subprocess.CompletedProcess[str]) -> str:
    """Exit 3 and exactly one error line on stderr (the_error_line), which is returned."""
    assert result.returncode == 3, result.stdout + result.stderr
    return the_error_line(result)


def shared_env(env: dict[str, str], lock_dir: Path, *pool: int) -> dict[str, str]:
    return {**env, LOCK_DIR_ENV: str(lock_dir), POOL_ENV: ",".join(map(str, pool))}


def make_shared_lock_dir(traversable_dir: Path) -> Path:
    """A mode-1777 lock directory that the users nobody and daemon can reach.

    ``traversable_dir`` is the conftest fixture, which requires those users.
    """
    path = traversable_dir / "locks"
    path.mkdir()
    os.chmod(path, 0o1777)
    return path
