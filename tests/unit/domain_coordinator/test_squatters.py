"""``squatters``: live processes that carry a domain ID in ROS_DOMAIN_ID without holding it.

A test that outlived its runner, or a shell's export, still talks on the domain. The scan
reads real processes' environments: it finds a process with ``ROS_DOMAIN_ID=N`` (the
value read as ROS reads it: ``0x10`` is 16), with its controls beside it, a process
without the variable and one whose variable only ends in the same name. ``ancestors``
tells a holder's own test from a squatter: it walks a real process tree upwards.
"""

from __future__ import annotations

import os
import sys

import pytest
from helpers.coordinator import wait_for_entry, wait_for_environment, without_domain_id
from helpers.domains import free_ids
from helpers.processes import Children

from ros_isolated_test.domain_coordinator.records import user_name
from ros_isolated_test.domain_coordinator.squatters import ancestors, domain_value, scan

#: Starts a grandchild (``sleep``), prints its PID, and waits for stdin to close.
PARENT_OF_A_SLEEPER = """
import subprocess, sys
sleeper = subprocess.Popen(["sleep", "600"])
print(sleeper.pid, flush=True)
sys.stdin.read()
sleeper.kill()
"""


@pytest.mark.parametrize(
    ("text", "domain_id"),
    [
        ("5", 5),
        ("0", 0),
        ("232", 232),
        (" 7", 7),  # leading blanks, as strtoul skips them
        ("0x10", 16),
        ("0X1f", 31),
        ("010", 8),  # a leading 0 is octal
        ("5abc", 5),  # the leading number, as strtoul reads it
        ("", None),
        ("abc", None),
        ("-1", None),
    ],
)
def test_a_value_is_read_as_ros_reads_it(text: str, domain_id: int | None) -> None:
    assert domain_value(text) == domain_id


def test_a_process_with_the_id_in_its_environment_is_found_and_one_without_is_not(
    children: Children,
) -> None:
    domain_id, other = free_ids(2)
    base = without_domain_id()
    squatter = children.start(["sleep", "600"], env={**base, "ROS_DOMAIN_ID": str(domain_id)})
    in_hex = children.start(["sleep", "601"], env={**base, "ROS_DOMAIN_ID": hex(domain_id)})
    # The controls: no variable, and a variable whose name only ends in ROS_DOMAIN_ID.
    plain = children.start(["sleep", "602"], env={**base, "CONTROL": "plain"})
    lookalike = f"X_ROS_DOMAIN_ID={domain_id}"
    similar = children.start(["sleep", "603"], env={**base, "X_ROS_DOMAIN_ID": str(domain_id)})
    wait_for_environment(squatter.pid, domain_id)
    wait_for_entry(in_hex.pid, f"ROS_DOMAIN_ID={hex(domain_id)}")
    wait_for_entry(plain.pid, "CONTROL=plain")
    wait_for_entry(similar.pid, lookalike)

    found = scan({domain_id, other})
    assert sorted(found) == [domain_id]
    by_pid = {item.pid: item for item in found[domain_id]}
    assert sorted(by_pid) == sorted([squatter.pid, in_hex.pid])
    first = by_pid[squatter.pid]
    assert (first.domain_id, first.user) == (domain_id, user_name(os.getuid()))
    assert first.command == "sleep 600"
    assert by_pid[in_hex.pid].command == "sleep 601"
    assert first.started > 0
    # Asked for another ID only, the scan names none of them; asked for all, it does.
    assert scan({other}) == {}
    assert {item.pid for item in scan().get(domain_id, [])} == set(by_pid)


def test_the_ancestors_of_a_process_are_its_parent_and_theirs(children: Children) -> None:
    parent = children.python(PARENT_OF_A_SLEEPER)
    grandchild = int(children.first_line(parent))
    found = ancestors(grandchild)
    assert {parent.pid, os.getpid()} <= found
    assert grandchild not in found
    # The control: the walk goes up only, never down to a child.
    assert os.getpid() in ancestors(parent.pid)
    assert grandchild not in ancestors(parent.pid)
    assert parent.pid not in ancestors(os.getpid())
    assert ancestors(sys.maxsize) == set()  # no such process: nothing to walk
    children.finish(parent)
