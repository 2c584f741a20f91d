"""DDS participants alive in this network namespace, seen through the UDP ports they bind.

Every DDS participant on domain D binds UDP ports computed from D (the RTPS port
mapping every ROS middleware on DDS uses: 7400 + 250*D for multicast discovery, 7401
for multicast user data, 7410/7411 + 250*D + 2*i for the unicast ports of the host's
i-th participant). ``/proc/net/udp`` and ``/proc/net/udp6`` list every socket of the
network namespace, whoever owns it and however its ID was chosen (environment, code,
a launch file), in one short read: a cost that grows with the sockets of the host,
not with its processes. A participant in another network namespace (a container
with a network of its own) is not seen, and cannot reach ours over UDP either.
"""

from __future__ import annotations

#: The RTPS well-known port mapping: port base, domain gain, and the offsets in use.
PORT_BASE = 7400
DOMAIN_GAIN = 250
_MULTICAST_OFFSETS = (0, 1)
_FIRST_UNICAST_OFFSET = 10
_TABLES = ("/proc/net/udp", "/proc/net/udp6")


def domain_of_port(port: int) -> int | None:
    """The domain whose RTPS ports include ``port``, or None for any other port."""
    if port < PORT_BASE:
        return None
    domain_id, offset = divmod(port - PORT_BASE, DOMAIN_GAIN)
    if offset in _MULTICAST_OFFSETS or offset >= _FIRST_UNICAST_OFFSET:
        return domain_id
    return None


def _local_ports(table: bytes) -> set[int]:
    """Local ports of a /proc/net/udp table (``sl local_address ...``, hex ``addr:port``)."""
    ports: set[int] = set()
    for line in table.splitlines()[1:]:
        fields = line.split(None, 2)
        if len(fields) < 2:
            continue
        _address, _colon, port = fields[1].rpartition(b":")
        try:
            ports.add(int(port, 16))
        except ValueError:
            continue
    return ports


def bound_domains() -> dict[int, list[int]]:
    """Each domain with a participant bound in this network namespace, with its ports.

    A table that cannot be read (no IPv6, no /proc) counts as empty: the other checks
    of the coordinator still stand.
    """
    found: dict[int, list[int]] = {}
    for path in _TABLES:
        try:
            with open(path, "rb") as table:
                data = table.read()
        except OSError:
            continue
        for port in _local_ports(data):
            domain_id = domain_of_port(port)
            if domain_id is not None:
                found.setdefault(domain_id, []).append(port)
    for ports in found.values():
        ports.sort()
    return found
