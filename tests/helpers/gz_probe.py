#!/usr/bin/env python3
"""A simulation test in miniature: listens on one Gazebo topic and publishes its own token.

Usage: gz_probe.py TOOL RENDEZVOUS TOKEN PEERS

TOOL is Gazebo's ``ign-transport-topic``. The probe listens on :data:`TOPIC` and
publishes TOKEN until it hears it itself (so its listener is live and silence means
isolation, not a broken transport); then it says it is ready (``RENDEZVOUS/ready-TOKEN``)
and waits until all PEERS probes are. Only then does it publish TOKEN :data:`AFTER_READY`
times more: every probe's listener is live for every one of those messages. It says it is
done and, once all are, stops listening. What it heard goes to ``RENDEZVOUS/heard-TOKEN``
(one token a line) and the partition variables it was given to
``RENDEZVOUS/partition-TOKEN``. The order of events decides, never a clock: the only
time limit (:data:`PATIENCE`) stops a probe whose peers never came.
Exit codes: 0 done, 3 never heard itself, 4 the peers never came.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

TOPIC = "/ros_isolated_test_probe"
MESSAGE_TYPE = "ignition.msgs.StringMsg"
#: Publications after everyone is ready: one would do; more make a missed one harmless.
AFTER_READY = 5
#: Publications allowed before the probe must have heard itself (each takes ~1 s).
SELF_TRIES = 60
#: Seconds to wait for peers: a hang stopper, never a verdict on a loaded machine.
PATIENCE = 300.0
_HEARD = re.compile(r'data: "([^"]*)"')


def heard(log: Path) -> set[str]:
    """Every token the listener printed so far."""
    return set(_HEARD.findall(log.read_text(errors="replace")))


def publish(tool: str, token: str) -> None:
    """One message, as a simulation's node would send it (the CLI waits for discovery)."""
    subprocess.run(
        [tool, "-t", TOPIC, "-m", MESSAGE_TYPE, "-p", f'data: "{token}"'],
        check=True,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        timeout=60,
    )


def all_there(rendezvous: Path, stage: str, peers: int) -> bool:
    return len(list(rendezvous.glob(f"{stage}-*"))) >= peers


def wait_for_all(rendezvous: Path, stage: str, peers: int) -> bool:
    deadline = time.monotonic() + PATIENCE
    while not all_there(rendezvous, stage, peers):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def main() -> int:
    tool, folder, token, count = sys.argv[1:]
    rendezvous = Path(folder)
    peers = int(count)
    names = ("GZ_PARTITION", "IGN_PARTITION")
    seen = "".join(f"{name}={os.environ.get(name, '-')}\n" for name in names)
    (rendezvous / f"partition-{token}").write_text(seen)
    log = rendezvous / f"listened-{token}.log"
    with log.open("wb") as out:
        listener = subprocess.Popen(
            [tool, "-e", "-t", TOPIC, "-d", "3600"], stdin=subprocess.DEVNULL, stdout=out
        )
    try:
        for _ in range(SELF_TRIES):
            publish(tool, token)
            if token in heard(log):
                break
        else:
            print(f"probe {token}: never heard itself on {TOPIC}", file=sys.stderr)
            return 3
        (rendezvous / f"ready-{token}").touch()
        if not wait_for_all(rendezvous, "ready", peers):
            print(f"probe {token}: the other probes never became ready", file=sys.stderr)
            return 4
        for _ in range(AFTER_READY):
            publish(tool, token)
        (rendezvous / f"done-{token}").touch()
        if not wait_for_all(rendezvous, "done", peers):
            print(f"probe {token}: the other probes never finished", file=sys.stderr)
            return 4
    finally:
        listener.terminate()
        listener.wait(60)
    tokens = sorted(heard(log))
    (rendezvous / f"heard-{token}").write_text("".join(f"{item}\n" for item in tokens))
    print(f"probe {token} heard: {' '.join(tokens)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
