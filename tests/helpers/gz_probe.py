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
``RENDEZVOUS/partition-TOKEN``.

The order of events decides, never a clock. A probe that fails says why in
``RENDEZVOUS/failed-TOKEN``, and its peers stop waiting for it at once, so one failure
ends the group with its reason instead of a hang. The only time limit
(:data:`PATIENCE`) stops a probe whose peers never came, well before the test's own.
A listener that dies, or has not heard its own probe for a while, is started again
(and said so): it is the transport's tool, not the thing under test.
Exit codes: 0 done, 3 never heard itself, 4 the peers never came or one failed.
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
#: Tries after which a listener that has not heard itself is started afresh.
FRESH_LISTENER_EVERY = 15
#: Seconds to wait for peers: a hang stopper, never a verdict on a loaded machine.
PATIENCE = 150.0
#: How a failure file starts when the transport failed, and when a peer did.
NEVER_HEARD = "never heard itself"
PEER_FAILED = "a peer failed"
_HEARD = re.compile(r'data: "([^"]*)"')


class ProbeFailed(Exception):
    """This probe cannot go on; the message says why (and goes to the rendezvous)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


class Listener:
    """``ign-transport-topic -e`` on :data:`TOPIC`, its output appended to one log."""

    def __init__(self, tool: str, log: Path) -> None:
        self.tool = tool
        self.log = log
        self.starts = 0
        self.process = self._start()

    def _start(self) -> subprocess.Popen[bytes]:
        self.starts += 1
        with self.log.open("ab") as out:
            return subprocess.Popen(
                [self.tool, "-e", "-t", TOPIC, "-d", "3600"],
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=out,
            )

    def keep_alive(self) -> None:
        """Starts the listener again if it died (said on stderr, for the test's log)."""
        code = self.process.poll()
        if code is not None:
            print(f"listener exited with {code}; starting it again", file=sys.stderr)
            self.process = self._start()

    def restart(self) -> None:
        """A fresh listener, in case this one missed the topic's discovery."""
        print("listener heard nothing yet; starting a fresh one", file=sys.stderr)
        self.stop()
        self.process = self._start()

    def heard(self) -> set[str]:
        """Every token the listener printed so far."""
        return set(_HEARD.findall(self.log.read_text(errors="replace")))

    def stop(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(60)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def publish(tool: str, token: str) -> None:
    """One message, as a simulation's node would send it; a failed one is only said."""
    try:
        done = subprocess.run(
            [tool, "-t", TOPIC, "-m", MESSAGE_TYPE, "-p", f'data: "{token}"'],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            timeout=30,
            check=False,
        )
    except subprocess.TimeoutExpired:
        print("publish hung for 30 s and was killed", file=sys.stderr)
        return
    if done.returncode != 0:
        print(f"publish exited with {done.returncode}: {done.stderr!r}", file=sys.stderr)


def wait_for_all(rendezvous: Path, stage: str, peers: int) -> None:
    """Returns once PEERS probes reached STAGE; raises if one failed or time ran out."""
    deadline = time.monotonic() + PATIENCE
    while len(list(rendezvous.glob(f"{stage}-*"))) < peers:
        failed = sorted(rendezvous.glob("failed-*"))
        if failed:
            reasons = "; ".join(f"{path.name}: {path.read_text().strip()}" for path in failed)
            raise ProbeFailed(4, f"{PEER_FAILED} before {stage}: {reasons}")
        if time.monotonic() > deadline:
            raise ProbeFailed(4, f"the other probes never reached {stage}")
        time.sleep(0.05)


def probe(tool: str, rendezvous: Path, token: str, peers: int) -> list[str]:
    """The whole exchange; returns every token heard."""
    listener = Listener(tool, rendezvous / f"listened-{token}.log")
    try:
        deadline = time.monotonic() + PATIENCE
        tries = 0
        while token not in listener.heard():
            if tries == SELF_TRIES or time.monotonic() > deadline:
                raise ProbeFailed(
                    3,
                    f"{NEVER_HEARD} on {TOPIC} after {tries} publications "
                    f"({listener.starts} listener start(s))",
                )
            if tries and tries % FRESH_LISTENER_EVERY == 0:
                listener.restart()
            listener.keep_alive()
            publish(tool, token)
            tries += 1
        (rendezvous / f"ready-{token}").touch()
        wait_for_all(rendezvous, "ready", peers)
        for _ in range(AFTER_READY):
            publish(tool, token)
        (rendezvous / f"done-{token}").touch()
        wait_for_all(rendezvous, "done", peers)
    finally:
        listener.stop()
    return sorted(listener.heard())


def main() -> int:
    tool, folder, token, count = sys.argv[1:]
    rendezvous = Path(folder)
    names = ("GZ_PARTITION", "IGN_PARTITION")
    seen = "".join(f"{name}={os.environ.get(name, '-')}\n" for name in names)
    (rendezvous / f"partition-{token}").write_text(seen)
    try:
        tokens = probe(tool, rendezvous, token, int(count))
    except ProbeFailed as failure:
        message, code = str(failure), failure.code
    except Exception as error:  # any other failure must still reach the peers
        message, code = f"{type(error).__name__}: {error}", 1
    else:
        (rendezvous / f"heard-{token}").write_text("".join(f"{item}\n" for item in tokens))
        print(f"probe {token} heard: {' '.join(tokens)}")
        return 0
    (rendezvous / f"failed-{token}").write_text(message + "\n")
    print(f"probe {token}: {message}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
