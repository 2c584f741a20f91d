"""A tiny file system that fills up for real: a tmpfs in a private mount namespace.

The mount lives only in a namespace made for one command (``unshare --mount
--propagation private``), so it dies with that command and never shows on the host.
Files on it are gone when the command ends: ``then`` runs in the namespace after it,
to copy out what a test needs to look at. Needs ``capabilities.MOUNT_NAMESPACE``.
"""

from __future__ import annotations

import os
import shlex
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

#: Exit code of the setup when the mount failed: never a product's code.
SETUP_FAILED = 97


def run_on_tiny_disk(
    mount_point: Path,
    argv: Sequence[str],
    env: Mapping[str, str],
    size: str = "64k",
    then: str = "",
    timeout: float = 120,
) -> subprocess.CompletedProcess[bytes]:
    """Run ``argv`` with a ``size`` tmpfs on ``mount_point``; ``then`` (shell) runs after it.

    Returns what ``argv`` returned: its exit code, its stdout and stderr as bytes.
    """
    mount_point.mkdir(parents=True, exist_ok=True)
    where = shlex.quote(str(mount_point))
    script = (
        f"mount -t tmpfs -o size={size},mode=1777 tmpfs {where} || exit {SETUP_FAILED}; "
        f'"$@"; code=$?; {then or ":"}; exit $code'
    )
    done = subprocess.run(
        ["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh", *argv],
        check=False,
        env=dict(env),
        capture_output=True,
        timeout=timeout,
    )
    assert done.returncode != SETUP_FAILED, done.stderr.decode(errors="replace")
    assert not os.path.ismount(mount_point), "a mount leaked out of its namespace"
    return done


def fill(mount_point: Path) -> str:
    """Shell words that fill the file system at ``mount_point`` to its last byte."""
    where = shlex.quote(str(mount_point / "filler"))
    return f"dd if=/dev/zero of={where} bs=1k 2>/dev/null; true"
