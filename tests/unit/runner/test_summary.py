"""``summary``: what a run says first, and records in its result: the ID, the partition, the mode.

One wording for the runner's output and the pytest plugin's header, so a reader who has
seen one knows the other. The first line starts as upstream's does (``Running with
ROS_DOMAIN_ID <id>``: what greps for it finds it), then says what keeps the test apart
where that is not the default; each line has its suite property beside it, so the result
file says what the console said. Domain isolation asked for by nobody says nothing new.
"""

from __future__ import annotations

import pytest

from ros_isolated_test.domain_coordinator.upstream import COLCON, Setter
from ros_isolated_test.runner import discovery, environment, partition, settings
from ros_isolated_test.runner.isolation import Lease
from ros_isolated_test.runner.summary import (
    NOTES_SEPARATOR,
    SETTINGS_NOTES,
    header_line,
    isolation_summary,
    resources_summary,
    summary,
)

UPSTREAM = "Running with ROS_DOMAIN_ID 5"


def _policy(**given: object) -> environment.Policy:
    """An isolated run's policy: the default discovery decision, then ``given``."""
    return environment.Policy(
        isolate=True,
        env={},
        notes=(),
        discovery=discovery.decide({}, None),
        **given,  # type: ignore[arg-type]
    )


@pytest.mark.parametrize(
    ("given", "reserved", "after"),
    [
        ({}, True, ""),
        ({"namespaces": True, "mode": "namespace"}, True, ", in namespaces of its own"),
        (
            {"namespaces": True, "mode": "namespace"},
            False,
            ", in namespaces of its own; ID 5 is not reserved (no ID of the pool is free): "
            "the namespaces isolate the test",
        ),
        (
            {"mode": "auto", "fallback": "as namespaces are not allowed here: no userns"},
            True,
            "; isolation auto: by the domain ID alone, no namespaces (see below)",
        ),
    ],
    ids=["domain", "namespace", "namespace-unreserved", "auto-fallback"],
)
def test_the_first_line_for_each_mode_starts_as_upstreams(
    given: dict[str, object], reserved: bool, after: str
) -> None:
    assert header_line(_policy(**given), 5, reserved) == UPSTREAM + after
    # With the Gazebo partition, named right after the ID, before the mode.
    gz_name = partition.for_this_runner(5)
    with_gz = header_line(_policy(gz_partition=True, **given), 5, reserved)
    assert with_gz == f"{UPSTREAM} (Gazebo partition {gz_name}){after}"


def test_an_isolated_run_says_its_discovery_partition_and_notes_and_records_them() -> None:
    policy = environment.Policy(
        isolate=True,
        env={},
        notes=("extra environment variables:",),
        discovery=discovery.decide({}, None),
        gz_partition=True,
    )
    config = settings.read({}, port_range=(32768, 60999))
    config.notes = ("IDs 1-3 left out", "another note")
    lines, properties = summary(policy, 5, config)
    gz_name = partition.for_this_runner(5)
    assert lines == [
        "discovery range LOCALHOST (set by the runner): DDS discovery stays on this machine",
        partition.describe(gz_name),
        "IDs 1-3 left out",
        "another note",
        "extra environment variables:",
    ]
    assert properties == {
        "ros_domain_id": "5",
        "ros_discovery_range": "LOCALHOST",
        "ros_discovery_range_source": "set by the runner",
        "gz_partition": gz_name,
        SETTINGS_NOTES: NOTES_SEPARATOR.join(config.notes),
    }  # no "isolation": the default says nothing new


@pytest.mark.parametrize(
    ("env", "domain", "gz"),
    [({}, "unset (0)", "unset"), ({"ROS_DOMAIN_ID": "42", "IGN_PARTITION": "mine"}, "42", "mine")],
)
def test_a_run_without_isolation_records_what_the_test_had(
    env: dict[str, str], domain: str, gz: str
) -> None:
    """The settings' notes concern the pool: not said when no ID was handed out."""
    policy = environment.Policy(isolate=False, env=env, notes=("WARNING: without isolation",))
    config = settings.read({}, port_range=(32768, 60999))
    config.notes = ("IDs 1-3 left out",)
    lines, properties = summary(policy, None, config)
    assert lines == ["WARNING: without isolation"]
    assert properties == {"ros_domain_id": domain, "isolation": "disabled", "gz_partition": gz}


def test_how_the_test_is_kept_apart_is_recorded_unless_by_default() -> None:
    assert isolation_summary(_policy(), 5, reserved=True) == ([], {})
    reserved = isolation_summary(_policy(namespaces=True, mode="namespace"), 5, True)
    assert reserved[1] == {"isolation": "namespace", "ros_domain_id_reserved": "yes"}
    (line,) = reserved[0]
    assert line.startswith("isolation namespace: network (loopback only), mount (a private")
    # What is its own and what is not, as measured (tests/e2e/test_namespace_boundary.py).
    own, not_own = line.split("are its own; ")
    assert own.endswith("its ports, multicast, abstract Unix sockets, /dev/shm and IPC ")
    assert not_own == (
        "files (a Unix socket bound to a path too) and processes (/proc, signals) are shared "
        "with the host"
    )
    shared = isolation_summary(_policy(namespaces=True, mode="auto"), 5, False)
    assert shared[1]["isolation"] == "namespace (auto)"
    assert shared[1]["ros_domain_id_reserved"].startswith("no: no ID of the pool is free")
    assert shared[0][1].startswith("ROS_DOMAIN_ID 5 is not reserved: no ID of the pool is free")
    fallback = isolation_summary(_policy(mode="auto", fallback="as namespaces cut it off"), 5, True)
    assert fallback == (
        ["isolation auto: by the domain ID alone, as namespaces cut it off"],
        {"isolation": "domain (auto: as namespaces cut it off)"},
    )


def test_what_is_held_besides_the_id_is_said_with_the_capacity_and_the_wait() -> None:
    config = settings.read({"ROS_ISOLATED_TEST_CAPACITY": "gpu=2"}, resources="gpu=1")
    line, properties = resources_summary(Lease(5, {"gpu": 1}, waited=2.0), config)
    assert line == "holding gpu=1 of gpu=2 (waited 2.0 s)"
    assert properties == {"resources": "gpu=1", "resources_waited": "2.000", "capacity": "gpu=2"}


def test_an_id_replaced_for_a_tool_is_said_on_the_first_line_and_recorded() -> None:
    """colcon's ID replaced: the first line names it, the next says why, the property both.
    The control: nothing replaced, nothing said."""
    colcon = Setter(COLCON, 4242, "colcon test", "14", 14, None)
    policy = _policy(replaced=colcon)
    assert header_line(policy, 5).endswith(
        ", replacing ROS_DOMAIN_ID 14 of colcon's domain-ID coordinator"
    )
    lines, properties = summary(policy, 5)
    said = [line for line in lines if line.startswith("ROS_DOMAIN_ID 14 was set by")]
    assert said == [
        "ROS_DOMAIN_ID 14 was set by colcon's domain-ID coordinator "
        "(colcon-ros-domain-id-coordinator), pid 4242, which gives one ID to all tests of a "
        "package, tests ctest runs at once: replaced by 5, an ID of this test's own; 14 stays "
        "colcon's while it holds it"
    ]
    assert properties["ros_domain_id_replaced"] == f"14: {said[0]}"
    plain = _policy()
    assert "replacing" not in header_line(plain, 5)
    assert "ros_domain_id_replaced" not in summary(plain, 5)[1]
