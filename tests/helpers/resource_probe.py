"""A test command for resource scheduling, and reading back what a set of them did.

Run as a program (the "test" a runner runs), it appends ``start <label>`` to a shared log,
waits for what it was told to wait for, then appends ``end <label>`` and exits 0. Each
line is one ``write`` to a file opened with ``O_APPEND``, so the log's order is the order
in which the events happened, whatever the clocks say: tests reason from that order, never
from times. A probe whose partners never come gives up after its fallback, logs ``gave-up``
and exits 1, so a scheduler that keeps them apart fails the test instead of hanging it.

    python resource_probe.py LOG LABEL [--await PREFIX COUNT]... [--batch N] [--until PATH]
                             [--hold SECONDS] [--fallback SECONDS]

- ``--await PREFIX COUNT``: wait until COUNT probes whose label starts with PREFIX started;
- ``--batch N``: labels are ``group.n``; the k-th probe of a group to start waits until the
  group has N * (k // N + 1) starts: probes of one group run together N at a time;
- ``--until PATH``: wait until PATH exists (a test's signal to let go);
- ``--hold SECONDS``: then stay that long (work that takes time, no timing asserted).

Only the standard library at the top: the program starts once per runner.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

PROBE = str(Path(__file__).resolve())
#: Longest a probe waits for its partners: a hang stopper, never a verdict on speed.
FALLBACK = 120.0
START, END, GAVE_UP = "start", "end", "gave-up"


def command(log: Path, label: str, *options: object) -> list[str]:
    """The argv of a probe labelled ``label`` logging into ``log``."""
    return [sys.executable, PROBE, str(log), label, *map(str, options)]


def events(log: Path) -> list[tuple[str, str]]:
    """The log as (event, label) pairs, in the order they happened."""
    if not log.exists():
        return []
    pairs = []
    for line in log.read_text().splitlines():
        event, _, label = line.partition(" ")
        pairs.append((event, label.split(" ")[0]))
    return pairs


def starts(log: Path, prefix: str = "") -> list[str]:
    """Labels of the probes (of ``prefix``) that started, in order."""
    return [label for event, label in events(log) if event == START and label.startswith(prefix)]


def ended(log: Path, label: str) -> bool:
    """Whether the probe ``label`` logged its end."""
    return (END, label) in events(log)


def peaks(
    log: Path, amounts: Mapping[str, Mapping[str, int]], names: Sequence[str]
) -> dict[str, int]:
    """The most of each of ``names`` that running probes held at any one moment.

    ``amounts`` is what each label asked for ({label: {name: amount}}); the pseudo-name
    ``running`` counts probes (each holds one domain ID). A probe runs from its start
    line to its end line, a span inside the time its runner held its resources, so a
    peak here above the capacity means the capacity was exceeded.
    """
    held = dict.fromkeys(names, 0)
    top = dict(held)
    for event, label in events(log):
        sign = {START: 1, END: -1}.get(event, 0)
        for name in names:
            amount = 1 if name == "running" else amounts[label].get(name, 0)
            held[name] += sign * amount
            top[name] = max(top[name], held[name])
    return top


def _append(log: str, line: str) -> None:
    fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, f"{line}\n".encode())
    finally:
        os.close(fd)


def _started(log: str) -> list[str]:
    with open(log, encoding="utf-8") as file:
        return [
            line.split(" ")[1] for line in file.read().splitlines() if line.startswith("start ")
        ]


def main(argv: Sequence[str]) -> int:
    log, label, rest = argv[0], argv[1], list(argv[2:])
    awaits: list[tuple[str, int]] = []
    batch, until, hold, fallback = 0, "", 0.0, FALLBACK
    while rest:
        option = rest.pop(0)
        if option == "--await":
            awaits.append((rest.pop(0), int(rest.pop(0))))
        elif option == "--batch":
            batch = int(rest.pop(0))
        elif option == "--until":
            until = rest.pop(0)
        elif option == "--hold":
            hold = float(rest.pop(0))
        elif option == "--fallback":
            fallback = float(rest.pop(0))
        else:
            print(f"resource_probe: unknown option {option}", file=sys.stderr)
            return 2
    _append(log, f"{START} {label} {os.getpid()} {os.environ.get('ROS_DOMAIN_ID', '-')}")
    if batch:
        group = label.split(".")[0] + "."
        mine = [name for name in _started(log) if name.startswith(group)].index(label)
        awaits.append((group, batch * (mine // batch + 1)))
    deadline = time.monotonic() + fallback

    def waiting() -> str:
        seen = _started(log)
        for prefix, count in awaits:
            if sum(name.startswith(prefix) for name in seen) < count:
                return f"{count} starts of {prefix!r}"
        return f"{until} to exist" if until and not os.path.exists(until) else ""

    while missing := waiting():
        if time.monotonic() > deadline:
            _append(log, f"{GAVE_UP} {label}")
            print(f"resource_probe {label}: gave up waiting for {missing}", file=sys.stderr)
            return 1
        time.sleep(0.02)
    time.sleep(hold)
    _append(log, f"{END} {label}")
    print(f"resource_probe {label}: done", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
