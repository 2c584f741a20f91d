"""``xunit.timeline``: what the runner records of each attempt for the report's timeline.

When each attempt ran (local ISO 8601 to the microsecond, with its zone, so instants
from several machines order as the times do), what it waited for first (an ID, or the
resources it asked for) and the pool its ID came from. Checked on the functions and on
real runs: runners that wait for an ID and for a CPU, recorded apart.
"""

from __future__ import annotations

import datetime
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import gate
from helpers.commands import run_cli, start_cli
from helpers.domains import free_ids
from helpers.processes import poll_until
from helpers.report_page import ISO_MICRO
from helpers.results import load_result

from ros_isolated_test.xunit.timeline import (
    DOMAIN_POOL,
    ENDED_AT,
    STARTED_AT,
    WAIT_DOMAIN,
    WAIT_RESOURCES,
    instant,
    timeline_properties,
)

GATE = Path(gate.__file__)


def test_instants_keep_the_microsecond_and_the_zone() -> None:
    now = time.time()
    text = instant(now)
    assert ISO_MICRO.match(text), text
    assert abs(datetime.datetime.fromisoformat(text).timestamp() - now) < 2e-6
    # Control: the suite's own timestamp keeps neither.
    assert not ISO_MICRO.match(instant(now)[:19])


def test_instants_order_as_the_times_do_whatever_the_zone() -> None:
    times = [1_790_000_000.0 + step for step in (0.0, 1e-6, 0.25, 0.999999, 1.0, 3600.5)]
    read_back = [datetime.datetime.fromisoformat(instant(when)).timestamp() for when in times]
    assert read_back == sorted(read_back)
    assert all(abs(back - when) < 2e-6 for back, when in zip(read_back, times, strict=True))


@pytest.mark.parametrize(
    ("zone", "said"),
    [
        ("UTC", "1970-01-01T00:00:00.250000+00:00"),
        ("Asia/Kolkata", "1970-01-01T05:30:00.250000+05:30"),
        ("America/St_Johns", "1969-12-31T20:30:00.250000-03:30"),
    ],
)
def test_an_instant_carries_its_hosts_zone(zone: str, said: str) -> None:
    """Three hosts, one instant: each writes its own local time, all read back the same."""
    probe = "from ros_isolated_test.xunit.timeline import instant; print(instant(0.25))"
    found = subprocess.run(
        [sys.executable, "-c", probe],
        env={**os.environ, "TZ": zone},
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    assert found == said
    assert datetime.datetime.fromisoformat(found).timestamp() == 0.25


def test_the_wait_is_split_into_for_an_id_and_for_resources() -> None:
    found = timeline_properties(100.0, 101.5, 3.0, 1.0, "102-110, 150")
    assert found == {
        STARTED_AT: instant(100.0),
        ENDED_AT: instant(101.5),
        WAIT_DOMAIN: "2.000",
        WAIT_RESOURCES: "1.000",
        DOMAIN_POOL: "102-110, 150",
    }
    held_none = timeline_properties(100.0, 100.0, 0.0, 0.0, "")
    assert DOMAIN_POOL not in held_none  # no ID held: no pool
    assert (held_none[WAIT_DOMAIN], held_none[WAIT_RESOURCES]) == ("0.000", "0.000")
    # Rounding never makes the wait for an ID negative.
    assert timeline_properties(0.0, 1.0, 1.0, 1.0004, "")[WAIT_DOMAIN] == "0.000"


def _gated(
    env: dict[str, str],
    root: Path,
    name: str,
    started: list[subprocess.Popen[bytes]],
    *options: str,
) -> None:
    """``run`` of a gate test (helpers/gate.py) named ``name``, in the background."""
    command = [sys.executable, str(GATE), str(root), name, "pass"]
    result = root / f"{name}.xml"
    log = root / f"{name}.log"
    start_cli(["run", "--junit-xml", str(result), *options, "--", *command], env, log, started)


def _queued(env: dict[str, str]) -> set[str]:
    """The gate tests whose runners wait in the queue, as ``status --json`` shows them."""
    rows = json.loads(run_cli(["status", "--json"], env).stdout)
    return {str(row["command"]).split()[-2] for row in rows if row["via"] == "queue"}


def test_each_wait_is_recorded_as_for_an_id_or_for_resources(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """One runner waits for the only ID of its pool, one for the only CPU while IDs are free."""
    one, two, three = free_ids(3)
    capacity = {**env, "ROS_ISOLATED_TEST_CAPACITY": "cpu=1"}
    id_env = {**capacity, "ROS_ISOLATED_TEST_DOMAINS": str(one)}
    cpu_env = {**capacity, "ROS_ISOLATED_TEST_DOMAINS": f"{two},{three}"}
    _gated(id_env, tmp_path, "holds_id", started)
    _gated(cpu_env, tmp_path, "holds_cpu", started, "--resources", "cpu=1")
    poll_until(lambda: len(list(tmp_path.glob("holds_*.ready.1"))) == 2, "both holders run")
    _gated(id_env, tmp_path, "waits_id", started)
    _gated(cpu_env, tmp_path, "waits_cpu", started, "--resources", "cpu=1")
    poll_until(lambda: _queued(id_env) == {"waits_id", "waits_cpu"}, "both waiters queued")
    # One at a time, so neither waiter is ever behind the other: each waits for one thing.
    for holder, waiter in (("holds_id", "waits_id"), ("holds_cpu", "waits_cpu")):
        (tmp_path / f"{holder}.go.1").touch()
        poll_until((tmp_path / f"{waiter}.ready.1").exists, f"{waiter} runs")
        (tmp_path / f"{waiter}.go.1").touch()
    assert [process.wait() for process in started] == [0, 0, 0, 0]
    found = {
        name: load_result(tmp_path / f"{name}.xml").properties
        for name in ("holds_id", "holds_cpu", "waits_id", "waits_cpu")
    }
    assert float(found["waits_id"]["wait_domain_seconds"]) > 0
    assert found["waits_id"]["wait_resources_seconds"] == "0.000"
    assert float(found["waits_cpu"]["wait_resources_seconds"]) > 0
    assert found["waits_cpu"]["wait_domain_seconds"] == "0.000"
    assert found["waits_cpu"]["resources"] == "cpu=1"
    # Control: who found what they asked for free waited for nothing.
    for name in ("holds_id", "holds_cpu"):
        assert found[name]["wait_domain_seconds"] == "0.000"
        assert found[name]["wait_resources_seconds"] == "0.000"
    # Each waiter started after its holder ended: the times say so, to the microsecond.
    for holder, waiter in (("holds_id", "waits_id"), ("holds_cpu", "waits_cpu")):
        for name in (holder, waiter):
            assert ISO_MICRO.match(found[name]["started_at"])
            assert ISO_MICRO.match(found[name]["ended_at"])
        ended = datetime.datetime.fromisoformat(found[holder]["ended_at"])
        assert ended <= datetime.datetime.fromisoformat(found[waiter]["started_at"])
    assert found["waits_id"]["domain_pool"] == str(one)
