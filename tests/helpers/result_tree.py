"""A results tree as a run of many tests leaves it, made quickly: for the report page's scale.

Real runs of thousands of tests take too long for a test or a benchmark, so the files
are written by the product's own serialiser from suites shaped as the runner records
them: a colcon layout (``<root>/<package>/test_results/<package>/<test>.xml``), each test
on a domain ID of a pool, never two at once on one ID, with the waits, resources,
attempts (a few flaky tests, a few failing with a message and output) and timestamps
``run`` writes. Deterministic: the same arguments give the same tree.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

from ros_isolated_test.domain_coordinator.pool import id_ranges
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.attempts import merge_attempts
from ros_isolated_test.xunit.model import Case, Outcome, Suite
from ros_isolated_test.xunit.timeline import instant, timeline_properties

#: When the made-up run starts (seconds since the epoch): any fixed time will do.
START = 1_790_000_000.0
FAILURE = "AssertionError: expected 10 messages on /chatter, got 9"


def write_tree(
    root: Path,
    files: int,
    cases_per_file: int,
    pool: range = range(1, 9),
    packages: int = 20,
    host: str | None = None,
    seed: int = 7,
) -> list[Path]:
    """Write ``files`` canonical result files of ``cases_per_file`` cases under ``root``.

    Every 50th test fails (one case, with a message and output), every 40th is flaky
    (its first attempt failed on another ID), every 30th holds ``cpu=1``.
    """
    chance = random.Random(seed)
    host = host or socket.gethostname()
    free_at = {domain: START for domain in pool}
    written: list[Path] = []
    for number in range(files):
        package = f"pkg_{number % packages:03d}"
        test = f"test_{number:05d}"
        attempts = 2 if number % 40 == 39 else 1
        suites: list[Suite] = []
        for attempt in range(1, attempts + 1):
            domain = min(free_at, key=lambda key: (free_at[key], key))
            waited = max(0.0, free_at[domain] - START - number * 0.05)
            started = free_at[domain] + 0.02
            duration = 0.2 + chance.random() * 3
            free_at[domain] = started + duration + 0.01
            failed = attempt < attempts or number % 50 == 49
            suites.append(
                _suite(
                    package,
                    test,
                    cases_per_file,
                    domain,
                    pool,
                    host,
                    started,
                    duration,
                    waited,
                    failed,
                    number % 30 == 29,
                )
            )
        suite = suites[0] if attempts == 1 else merge_attempts(suites)
        path = root / package / "test_results" / package / f"{test}.xml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(serialise.serialize(suite))
        written.append(path)
    return written


def _suite(
    package: str,
    test: str,
    count: int,
    domain: int,
    pool: range,
    host: str,
    started: float,
    duration: float,
    waited: float,
    failed: bool,
    heavy: bool,
) -> Suite:
    name = f"{package}.{test}"
    cases = [
        Case(f"{name}.TestNode", f"test_case_{index:05d}", time=duration / max(count, 1))
        for index in range(count)
    ]
    properties = {
        "command": f"python3 -m pytest test/{test}.py",
        "ros_domain_id": str(domain),
        "ros_discovery_range": "LOCALHOST",
        "exit": "exited with code 1" if failed else "exited with code 0",
        "exit_code": "1" if failed else "0",
        "duration": f"{duration:.3f}",
    }
    if heavy:
        properties.update({"resources": "cpu=1", "capacity": "cpu=2"})
    properties.update(
        timeline_properties(started, started + duration, waited, 0.0, id_ranges(pool))
    )
    if failed and cases:
        first = cases[0]
        first.outcome = Outcome.FAILURE
        first.message = FAILURE
        first.text = f"Traceback (most recent call last):\n  ...\n{FAILURE}"
        first.system_out = "\n".join(f"[talker] published {i}" for i in range(40))
    return Suite(
        name=name,
        cases=cases,
        time=duration,
        timestamp=instant(started)[:19],
        hostname=host,
        properties={**properties, "domain_pool": id_ranges(pool)},
    )


def write_failing_tree(root: Path, files: int, size: int = 20 * 1024) -> list[Path]:
    """``files`` result files of ours, each one test of one failing case, shaped as a run
    leaves them (``write_tree``'s layout and properties), whose message, text and output
    are ``size`` characters each (60 KB a failure by default): every file fails."""
    written: list[Path] = []
    chance = random.Random(files)
    for number in range(files):
        package = f"pkg_{number % 20:03d}"
        name = f"{package}.test_{number:05d}"
        started = START + number * 0.5
        words = "".join(chance.choice("abcdefghij ") for _ in range(64))
        case = Case(
            f"{name}.TestNode",
            "test_case",
            time=0.4,
            outcome=Outcome.FAILURE,
            message=(FAILURE + " " + words * (size // 64 + 1))[:size],
            text=("Traceback (most recent call last):\n" + words * (size // 64 + 1))[:size],
            system_out=("[talker] " + words * (size // 64 + 1))[:size],
        )
        properties = {
            "ros_domain_id": str(1 + number % 8),
            "ros_discovery_range": "LOCALHOST",
            "exit": "exited with code 1",
            **timeline_properties(started, started + 0.4, 0.0, 0.0, "1-8"),
        }
        suite = Suite(name, [case], 0.4, instant(started)[:19], "host", properties)
        path = root / package / "test_results" / package / f"test_{number:05d}.xml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(serialise.serialize(suite))
        written.append(path)
    return written
