"""``cli.status_table``: what ``ros-isolated-test status`` prints, the table or its JSON.

The coordinator reads what is in use; this draws it. Each kind of use is a row saying
what holds the ID (a runner, a port, a participant with its UDP ports, a squatter, a
survivor), a runner's row with the Gazebo partition its test has (rebuilt from the
holder record, as the runner made it), then the waiters in line and, only while
resources are in play, the capacity and the holds. ``--json`` carries the same rows.
The drawing is checked on status read as data; the partition on a real held run.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from helpers.commands import run_cli, start_cli
from helpers.coordinator import STATUS_COLUMNS, status_rows
from helpers.processes import poll_until

from ros_isolated_test.cli.status_table import as_json, gz_partition, table
from ros_isolated_test.domain_coordinator.queue import Waiter
from ros_isolated_test.domain_coordinator.records import Holder, iso_time
from ros_isolated_test.domain_coordinator.resource_holds import Hold
from ros_isolated_test.domain_coordinator.status import DomainUse, MachineStatus
from ros_isolated_test.runner import partition

LOCK_DIR = Path("/tmp/locks-of-this-test")
#: 2024-01-01 at noon UTC: any time zone shows it as a time of that day.
NOON = 1704110400.0
RUNNER = Holder(7, 4242, "alice", "ros2 test pkg", NOON, "build-host")
SQUATTER = Holder(8, 5151, "bob", "sleep 600", NOON, "")
SURVIVOR = Holder(9, 6161, "root", "(setuid_helper)", NOON, "")
USES = [
    DomainUse(7, "lock", RUNNER),
    DomainUse(8, "port", None),
    DomainUse(8, "environment", SQUATTER),
    DomainUse(9, "participant", None, (9660, 9661)),
    DomainUse(9, "survivor", SURVIVOR),
    DomainUse(10, "lock", None),
]
WAITERS = [
    Waiter(1, 300, "carol", "ros2 test a", NOON, "h"),
    Waiter(2, 301, "dave", "ros2 test b", NOON, "h", {"gpu": 1}),
]
HOLDS = [
    Hold(400, "erin", "ros2 test gpu", NOON, "h", {"gpu": 1}, {"gpu": 1}, 7),
    Hold(401, "frank", "ros2 test kept", NOON, "h", {"cpu": 2}, {"cpu": 4}, None, (99,)),
]


def _status(
    uses: list[DomainUse],
    waiters: list[Waiter] | None = None,
    holds: list[Hold] | None = None,
    in_play: bool = False,
) -> MachineStatus:
    capacity = {"cpu": 4, "gpu": 1}
    return MachineStatus(LOCK_DIR, uses, waiters or [], None, holds or [], capacity, in_play)


def test_a_machine_with_nothing_in_use_is_one_line_naming_the_lock_dir() -> None:
    assert table(_status([])) == f"No domain ID of the pool is held (lock directory {LOCK_DIR})."
    assert json.loads(as_json(_status([]))) == []


def test_each_use_is_a_row_naming_what_holds_the_id() -> None:
    name = partition.name("build-host", 7, 4242)
    assert gz_partition(USES[0]) == name
    assert [gz_partition(use) for use in USES[1:]] == [None] * 5  # only a runner's test has one
    header, *rows = table(_status(USES)).splitlines()
    assert header.split() == STATUS_COLUMNS
    started = iso_time(NOON)
    assert [row.split()[:6] for row in rows] == [
        ["7", "runner", "4242", "alice", started, name],
        ["8", "port", "-", "-", "-", "-"],
        ["8", "squatter", "5151", "bob", started, "-"],
        ["9", "participant", "-", "-", "-", "-"],
        ["9", "survivor", "6161", "root", started, "-"],
        ["10", "runner", "-", "-", "-", "-"],
    ]
    assert rows[0].endswith(f"{name}  ros2 test pkg")
    assert rows[1].endswith("port 32768+ID taken (upstream domain_coordinator or another program)")
    assert rows[3].endswith("a DDS participant (UDP ports 9660, 9661) outside any runner")
    assert rows[5].endswith("held (no holder record)")
    # Columns line up: the partition column is as wide as the longest name in it.
    column = header.index("COMMAND")
    assert column > header.index("GZ_PARTITION") + len(name)
    commands = ["ros2 test pkg", "port 32768", "sleep 600", "a DDS", "(setuid_helper)", "held"]
    assert [row.index(command) for row, command in zip(rows, commands, strict=True)] == [column] * 6


def test_the_json_rows_are_the_table_as_data() -> None:
    rows = json.loads(as_json(_status(USES)))
    assert rows[0] == {
        "domain_id": 7,
        "via": "lock",
        **RUNNER.as_dict(),
        "gz_partition": partition.name("build-host", 7, 4242),
    }
    assert rows[1] == {"domain_id": 8, "via": "port"}
    assert rows[2] == {"domain_id": 8, "via": "environment", **SQUATTER.as_dict()}
    assert rows[3] == {"domain_id": 9, "via": "participant", "ports": [9660, 9661]}
    assert rows[4] == {"domain_id": 9, "via": "survivor", **SURVIVOR.as_dict()}
    assert rows[5] == {"domain_id": 10, "via": "lock"}


def test_waiters_follow_in_line_with_what_they_ask_for() -> None:
    shown = table(_status(USES[:1], WAITERS)).splitlines()
    start = shown.index("Waiting for a domain ID (2, first come, first served):")
    assert shown[start + 1].split() == ["POS", "PID", "USER", "WAITING", "SINCE", "COMMAND"]
    assert [line.split()[:3] for line in shown[start + 2 :]] == [
        ["1", "300", "carol"],
        ["2", "301", "dave"],
    ]
    assert shown[start + 2].endswith(" ros2 test a")
    assert shown[start + 3].endswith(" [gpu=1] ros2 test b")
    rows = json.loads(as_json(_status([], WAITERS)))
    assert rows == [{**waiter.as_dict(), "domain_id": None, "via": "queue"} for waiter in WAITERS]
    # The control: nobody waits, no such section.
    assert "Waiting for a domain ID" not in table(_status(USES[:1]))


def test_resources_are_shown_only_while_in_play() -> None:
    shown = table(_status([], [], HOLDS, in_play=True)).splitlines()
    start = shown.index("Resources (capacity cpu=4,gpu=1):")
    assert shown[start + 1].split() == ["PID", "USER", "SINCE", "ID", "HOLDS", "COMMAND"]
    assert shown[start + 2].split()[:2] == ["400", "erin"]
    assert shown[start + 2].split()[3:5] == ["7", "gpu=1"]
    assert shown[start + 3].split()[3:5] == ["-", "cpu=2"]
    assert shown[start + 3].endswith("(survivors 99) ros2 test kept")
    rows = json.loads(as_json(_status([], [], HOLDS, in_play=True)))
    assert [row["via"] for row in rows] == ["hold", "hold", "capacity"]
    assert rows[1]["survivors"] == [99]
    assert rows[2] == {"via": "capacity", "domain_id": None, "capacity": {"cpu": 4, "gpu": 1}}
    nothing_held = table(_status([], in_play=True)).splitlines()
    assert nothing_held[-2:] == ["Resources (capacity cpu=4,gpu=1):", "  none held"]
    # The control: resources not in play, no section and no capacity row.
    assert "Resources" not in table(_status([]))
    assert json.loads(as_json(_status([]))) == []


def test_status_shows_the_gazebo_partition_a_held_run_gave_its_test(
    one_id: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """Rebuilt from the holder record (host, ID, PID): the very name the test has."""
    seen = tmp_path / "seen"
    script = f'echo "$GZ_PARTITION" > {seen}.tmp && mv {seen}.tmp {seen} && sleep 60'
    holder = start_cli(["run", "--", "sh", "-c", script], one_id, tmp_path / "h.log", started)
    poll_until(seen.exists, "the held test never started")
    name = seen.read_text().strip()
    assert name.startswith("rit_"), name  # the control: the test has a partition
    (row,) = [row for row in status_rows(one_id) if row.get("pid") == holder.pid]
    assert row["via"] == "lock"
    assert row["gz_partition"] == name
    table = run_cli(["status"], one_id).stdout
    assert "GZ_PARTITION" in table.splitlines()[0], table
    (line,) = [line for line in table.splitlines() if f" {holder.pid} " in line]
    assert f" {name} " in line, table


def test_an_upstream_coordinators_id_is_named_as_its_and_a_replacement_beside_the_runner() -> None:
    """colcon's coordinator, upstream's runner, Kilted's fixture: each named as itself (a
    squatter otherwise); a runner whose test got its ID in place of colcon's says so."""
    colcon = Holder(11, 700, "alice", "colcon test", NOON, "")
    runner = Holder(12, 701, "alice", "python3 run_test_isolated.py r.xml", NOON, "h")
    uses = [
        DomainUse(11, "colcon", colcon),
        DomainUse(12, "lock", runner, replaced="11 (colcon's domain-ID coordinator)"),
        DomainUse(13, "upstream", Holder(13, 702, "bob", "python3 run_test_isolated.py", NOON, "")),
        DomainUse(14, "fixture", Holder(14, 703, "bob", "run_rmw_isolated sh", NOON, "")),
        DomainUse(15, "lock", RUNNER),  # the control: no replacement, nothing said
    ]
    _, *rows = table(_status(uses)).splitlines()
    assert [row.split()[:3] for row in rows] == [
        ["11", "colcon", "700"],
        ["12", "runner", "701"],
        ["13", "upstream", "702"],
        ["14", "rmw", "fixture"],
        ["15", "runner", "4242"],
    ]
    assert rows[1].endswith(
        "[replaced colcon's ROS_DOMAIN_ID 11] python3 run_test_isolated.py r.xml"
    )
    assert rows[4].endswith("  ros2 test pkg")
    data = json.loads(as_json(_status(uses)))
    assert data[1]["replaced"] == "11 (colcon's domain-ID coordinator)"
    assert [row.get("replaced") for row in data if row is not data[1]] == [None] * 4
    assert [row["via"] for row in data] == ["colcon", "lock", "upstream", "fixture", "lock"]
