"""Real survivors: processes a runner cannot end, and finding them again by a tag.

A runner run as nobody may not signal a setuid-root process its test started, so that
process outlives the runner's final sweep for real (no SIGKILL reaches it): the
supervisor names it a survivor and the ID stays blocked while it lives. Every such
process carries a tag of its own in its command line, so a test can check "nothing
survived" across the machine and its teardown can kill whatever carries the tag.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import signal
import stat
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from helpers import capabilities
from helpers.processes import DEADLINE

#: A setuid-root helper: the test's main process returns once its child has become
#: root for real (real, effective and saved UID 0), so the runner's user may not
#: signal it (EPERM). argv[1]: the tag, only to find it.
SETUID_HELPER = r"""
#define _GNU_SOURCE
#include <signal.h>
#include <unistd.h>
int main(int argc, char **argv) {
    int ready[2];
    char byte;
    (void)argc; (void)argv;
    if (pipe(ready) != 0) return 2;
    pid_t child = fork();
    if (child < 0) return 2;
    if (child > 0) {
        close(ready[1]);
        return read(ready[0], &byte, 1) == 1 ? 0 : 3;
    }
    close(ready[0]);
    if (setresuid(0, 0, 0) != 0) return 4;
    if (write(ready[1], "x", 1) != 1) return 5;
    close(ready[1]);
    for (;;) pause();
}
"""


def build_setuid_helper(folder: Path) -> Path:
    """``folder/setuid_helper``, setuid root (folder must be one other users can reach)."""
    capabilities.require(capabilities.OTHER_USERS, capabilities.SETUID_HELPER)
    source = folder / "setuid_helper.c"
    source.write_text(SETUID_HELPER)
    helper = folder / "setuid_helper"
    subprocess.run(["gcc", "-O", "-o", str(helper), str(source)], check=True, timeout=DEADLINE)
    os.chown(helper, 0, 0)
    os.chmod(helper, 0o4755)
    assert helper.stat().st_mode & stat.S_ISUID
    return helper


def new_tag() -> str:
    """A tag unique to one test (a number ``sleep`` accepts, so sleep can carry it too)."""
    return f"9999.{secrets.randbelow(10**12):012d}"


def alive_with(tag: str) -> list[int]:
    """Every running (not zombie) process on the machine with ``tag`` in its command line."""
    found: list[int] = []
    me = os.getpid()
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) == me:
            continue
        try:
            with open(f"/proc/{name}/cmdline", "rb") as handle:
                command = handle.read()
            with open(f"/proc/{name}/stat", "rb") as handle:
                state = handle.read().rsplit(b")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if tag.encode() in command.split(b"\0") and state not in (b"Z", b"X"):
            found.append(int(name))
    return found


def kill_all_with(tag: str) -> None:
    """SIGKILL every process carrying ``tag`` until none is left (teardown, whatever happened)."""
    deadline = time.monotonic() + DEADLINE
    while pids := alive_with(tag):
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, os.WNOHANG)  # ours when this process is a subreaper
        if time.monotonic() > deadline:
            pytest.fail(f"processes tagged {tag} would not die: {pids}")
        time.sleep(0.02)


@contextlib.contextmanager
def tagged() -> Iterator[str]:
    """A new tag; every process carrying it is killed when the block ends."""
    tag = new_tag()
    try:
        yield tag
    finally:
        kill_all_with(tag)
