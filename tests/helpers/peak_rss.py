"""A command's peak memory, as ``wait4`` reports it, never charged with pytest's own.

Linux carries a process's peak RSS across ``fork`` and ``exec``: a child of pytest
reports at least pytest's peak, which grows with every test that ran before it in the
session. So the command is started by a small interpreter of its own, whose ``wait4``
sees only the command and the descendants it waited for.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

#: Runs argv[4:] with stdout/stderr into argv[1]/argv[2] (empty: /dev/null), kills its
#: session after argv[3] seconds, and prints exit code, peak RSS, wall time, timed out.
_MEASURE = """
import json, os, signal, subprocess, sys, time
out, err, limit = sys.argv[1], sys.argv[2], float(sys.argv[3])
streams = [open(path, "wb") if path else subprocess.DEVNULL for path in (out, err)]
started = time.monotonic()
process = subprocess.Popen(
    sys.argv[4:], stdin=subprocess.DEVNULL, stdout=streams[0], stderr=streams[1],
    start_new_session=True,
)
timed_out = False
while True:
    pid, status, usage = os.wait4(process.pid, os.WNOHANG)
    if pid:
        break
    if time.monotonic() - started > limit:
        timed_out = True
        os.killpg(process.pid, signal.SIGKILL)
        _, status, usage = os.wait4(process.pid, 0)
        break
    time.sleep(0.02)
print(json.dumps([os.waitstatus_to_exitcode(status), usage.ru_maxrss * 1024,
                  time.monotonic() - started, timed_out]))
"""


class Peak:
    """How a measured command ended, and the most memory it (or a waited child) held."""

    def __init__(self, returncode: int, max_rss: int, wall: float, timed_out: bool) -> None:
        self.returncode = returncode
        #: Bytes: the largest RSS of the command and of every descendant it waited for.
        self.max_rss = max_rss
        self.wall = wall
        self.timed_out = timed_out


def measure(
    argv: Sequence[str],
    *,
    env: Mapping[str, str] | None = None,
    cwd: Path | None = None,
    stdout: Path | None = None,
    stderr: Path | None = None,
    timeout: float = 600.0,
) -> Peak:
    """Run ``argv`` (output into the given files, else discarded) and measure it."""
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            _MEASURE,
            str(stdout or ""),
            str(stderr or ""),
            str(timeout),
            *argv,
        ],
        env=None if env is None else dict(env),
        cwd=cwd,
        check=True,
        capture_output=True,
        text=True,
        timeout=timeout + 60,
    )
    returncode, max_rss, wall, timed_out = json.loads(done.stdout)
    return Peak(int(returncode), int(max_rss), float(wall), bool(timed_out))
