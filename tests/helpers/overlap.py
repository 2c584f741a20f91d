"""Proving that runners started at once never hand one domain ID to two tests at a time.

Each test command is :data:`PROBE`. It claims ``<board>/held/<ROS_DOMAIN_ID>`` with
``O_CREAT|O_EXCL``: a second test on the same ID finds the file there and records a
collision. Only then does it say it has tried (``claims/<label>``), and it holds the file
until every probe of the run has tried. So no holder lets go before all the others have
made their attempt: every probe that got an ID held it at the same instant as all the
others, and a shared ID always shows up as a collision. No clock decides anything; the
deadline only ends a probe whose peers never came.

:func:`run_at_once` starts all the commands together inside one private network and PID
namespace (this file is the launcher there, run as a script with nothing but the
standard library): ports 32768+ID and the processes a runner sees are then those of the
run alone, whatever else the machine runs.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

#: A test command. argv: board, label, how many probes the run has.
PROBE = """
import json, os, sys, time
board, label, total = sys.argv[1], sys.argv[2], int(sys.argv[3])
domain = os.environ.get("ROS_DOMAIN_ID", "<unset>")
record = {"label": label, "domain": domain}
def put(folder, data):
    with open(os.path.join(board, folder, label), "x") as out:
        json.dump(data, out)
held = os.path.join(board, "held", domain)
try:
    fd = os.open(held, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
except FileExistsError:
    try:
        with open(held) as mine:
            holder = mine.read()
    except OSError:
        holder = "?"
    put("collisions", {**record, "holder": holder})
    put("claims", record)
    sys.exit(f"COLLISION: ROS_DOMAIN_ID {domain} is held by {holder!r} too")
os.write(fd, label.encode())
os.close(fd)
put("claims", record)
deadline = time.monotonic() + 90
while len(os.listdir(os.path.join(board, "claims"))) < total:
    if time.monotonic() > deadline:
        break
    time.sleep(0.05)
record["all_held_at_once"] = len(os.listdir(os.path.join(board, "claims"))) >= total
os.unlink(held)
put("records", record)
"""

#: Only stops a hung run; no verdict depends on it.
HUNG = 180


@dataclass(frozen=True)
class Job:
    """One command of a run: a runner with a probe as its test."""

    label: str
    argv: Sequence[str]
    env: Mapping[str, str]


@dataclass(frozen=True)
class Done:
    """How one job ended: its exit code and everything it printed."""

    label: str
    returncode: int
    output: str


@dataclass(frozen=True)
class Board:
    """The directory the probes of one run write to, and what they wrote there."""

    root: Path
    #: How many probes the run has: each holds its ID until that many have tried.
    total: int

    def __post_init__(self) -> None:
        for folder in ("held", "claims", "records", "collisions"):
            (self.root / folder).mkdir(parents=True, exist_ok=True)

    def probe(self, label: str) -> list[str]:
        """The probe as a test command (an isolated Python: no site, so it starts fast)."""
        return [sys.executable, "-I", "-S", "-c", PROBE, str(self.root), label, str(self.total)]

    def read(self, folder: str) -> dict[str, dict[str, object]]:
        """The records of one folder, by label."""
        return {path.name: json.loads(path.read_text()) for path in (self.root / folder).iterdir()}

    @property
    def records(self) -> dict[str, dict[str, object]]:
        return self.read("records")

    @property
    def collisions(self) -> dict[str, dict[str, object]]:
        return self.read("collisions")


def run_at_once(jobs: Sequence[Job], where: Path) -> dict[str, Done]:
    """Start every job at once (in order) in a private network and PID namespace; wait all.

    Needs root and unshare (capabilities.NETWORK_NAMESPACES and UNSHARE). The namespace's
    first process is this file's launcher: when it ends, the kernel kills whatever is left.
    """
    where.mkdir(parents=True, exist_ok=True)
    spec = where / "jobs.json"
    codes = where / "codes.json"
    logs = {job.label: where / f"{job.label}.log" for job in jobs}
    spec.write_text(
        json.dumps(
            {
                "codes": str(codes),
                "jobs": [
                    {
                        "label": j.label,
                        "argv": list(j.argv),
                        "env": dict(j.env),
                        "log": str(logs[j.label]),
                    }
                    for j in jobs
                ],
            }
        )
    )
    unshare = ["unshare", "--net", "--pid", "--fork", "--mount-proc", "--kill-child"]
    launcher = [*unshare, sys.executable, "-I", "-S", __file__, str(spec)]
    done = subprocess.run(launcher, capture_output=True, text=True, timeout=HUNG, check=False)
    assert done.returncode == 0, f"the launcher failed:\n{done.stdout}{done.stderr}"
    returncodes: dict[str, int] = json.loads(codes.read_text())
    return {
        label: Done(label, returncodes[label], logs[label].read_text(errors="replace"))
        for label in logs
    }


def _launch(spec_path: str) -> None:
    """In the namespaces: bring loopback up, start every job, wait for all, write codes."""
    spec = json.loads(Path(spec_path).read_text())
    # A fresh network namespace has loopback down: nothing could bind 127.0.0.1.
    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    started = []
    for job in spec["jobs"]:
        with open(job["log"], "wb") as log:
            process = subprocess.Popen(
                job["argv"],
                env=job["env"],
                cwd=Path(job["log"]).parent,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        started.append((job["label"], process))
    codes = {}
    deadline = time.monotonic() + HUNG - 30
    for label, process in started:
        try:
            codes[label] = process.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            process.kill()
            codes[label] = process.wait()
    Path(spec["codes"]).write_text(json.dumps(codes))


if __name__ == "__main__":
    _launch(sys.argv[1])
