"""``participants``: DDS participants seen through the UDP ports they bind, and the mapping.

The coordinator never hands out an ID a participant in this network namespace is bound
to, however the participant chose it: from ROS_DOMAIN_ID, or in code, where no look at
processes' environments could ever see it. Each refusal has its control: the same ID is
handed out once the participant has gone.
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
from helpers import capabilities
from helpers.commands import run_cli
from helpers.coordinator import status_rows, without_domain_id
from helpers.domains import free_ids
from helpers.processes import Children

from ros_isolated_test.domain_coordinator import (
    LOCK_DIR_ENV,
    POOL_ENV,
    DomainCoordinator,
    participants,
)
from ros_isolated_test.domain_coordinator.participants import domain_of_port

#: A real participant on a domain chosen in code (argv[1]), not in its environment;
#: prints "up" once its node exists, and leaves when stdin closes.
PARTICIPANT_IN_CODE = """
import sys
import rclpy
from rclpy.context import Context
from rclpy.signals import SignalHandlerOptions
context = Context()
rclpy.init(args=[], context=context, domain_id=int(sys.argv[1]),
           signal_handler_options=SignalHandlerOptions.NO)
node = rclpy.create_node("participant_in_code", context=context)
print("up", flush=True)
sys.stdin.read()
node.destroy_node()
rclpy.shutdown(context=context)
"""


@pytest.mark.parametrize(
    ("port", "domain_id"),
    [
        (7399, None),  # below the mapping (Fast DDS's own 7000+ ports are there)
        (7400, 0),  # multicast discovery
        (7401, 0),  # multicast user data
        (7402, None),  # unused offsets 2-9
        (7409, None),
        (7410, 0),  # participant 0's unicast ports
        (7411, 0),
        (7649, 0),  # the last port of domain 0's range
        (7650, 1),
        (7400 + 250 * 232 + 11, 232),
    ],
)
def test_ports_map_to_the_domain_whose_rtps_ports_they_are(
    port: int, domain_id: int | None
) -> None:
    assert domain_of_port(port) == domain_id


def test_a_bound_udp_port_shows_its_domain_and_a_closed_one_does_not() -> None:
    """The reader parses the kernel's real table: IPv4 here, the wildcard address."""
    (domain_id,) = free_ids(1)
    port = 7410 + 250 * domain_id + 2 * 40  # participant 40: unlikely used by anything
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", port))
        assert port in participants.bound_domains().get(domain_id, [])
    assert port not in participants.bound_domains().get(domain_id, [])


@capabilities.RCLPY
def test_a_participant_whose_id_was_chosen_in_code_blocks_it(
    lock_dir: Path, children: Children
) -> None:
    """No environment names the domain: only its bound ports show it."""
    domain_id, other = free_ids(2)
    participant = children.python(PARTICIPANT_IN_CODE, domain_id, env=without_domain_id())
    assert children.first_line(participant) == "up"
    assert domain_id in participants.bound_domains()

    coordinator = DomainCoordinator(lock_dir, (domain_id,))
    assert coordinator.try_reserve(["x"]) is None
    with DomainCoordinator(lock_dir, (domain_id, other)).reserve(["x"]) as reservation:
        assert reservation.domain_id == other
    # status names it, with the ports it binds, and the refusal says why.
    env = {**without_domain_id(), LOCK_DIR_ENV: str(lock_dir), POOL_ENV: str(domain_id)}
    rows = status_rows(env)
    (row,) = [row for row in rows if row["domain_id"] == domain_id]
    assert row["via"] == "participant"
    ports = row["ports"]
    assert isinstance(ports, list)
    assert ports and all(domain_of_port(port) == domain_id for port in ports)
    refused = run_cli(["run", "--wait-timeout", "0", "--", "true"], env)
    assert refused.returncode == 3, refused.stderr
    assert f"{domain_id}: DDS participant on UDP" in refused.stderr

    # The control: the same ID, once the participant has left.
    assert children.finish(participant) == 0
    with coordinator.reserve(["x"]) as reservation:
        assert reservation.domain_id == domain_id
