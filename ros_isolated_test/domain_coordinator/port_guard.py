"""The TCP port that upstream's ``domain_coordinator`` uses to claim a domain ID.

Upstream claims ID N by binding TCP port 32768+N. Binding the same port while we hold
N keeps upstream's runner off our ID, and failing to bind it tells us upstream (or
another program) has N, so both coordinators can share one machine. Which socket holds
it (:func:`holding_sockets`) tells whose claim it is: the port lies in Linux's default
ephemeral range, so anything may hold it for a while. Only Linux 6.8 and later show a
socket that is bound and does not listen, as the coordinators' are
(:func:`shows_bound_sockets`).
"""

from __future__ import annotations

# The C socket type itself: the ``socket`` module's import (enum conversions of every
# constant) costs a test's runner more than the bind. Its sockets are close-on-exec.
import _socket

PORT_BASE = 32768


def claim_port(domain_id: int) -> _socket.socket | None:
    """Bind port 32768+ID on all interfaces, as upstream does; None when it is taken.

    No SO_REUSEADDR, like upstream, so a bound-but-idle socket on either side blocks
    the other. The socket is not inheritable: the test process must not keep it.
    """
    sock = _socket.socket(_socket.AF_INET, _socket.SOCK_STREAM)
    try:
        sock.bind(("", PORT_BASE + domain_id))
    except OSError:
        sock.close()
        return None
    return sock


def port_is_taken(domain_id: int) -> bool:
    """Whether something else holds the ID's port right now."""
    sock = claim_port(domain_id)
    if sock is None:
        return True
    sock.close()
    return False


#: sock_diag's numbers (linux/sock_diag.h, inet_diag.h, tcp_states.h): a dump of TCP
#: sockets listening (10) or bound and idle (13, TCP_BOUND_INACTIVE, Linux 6.8 and later).
_NETLINK_SOCK_DIAG = 4
_SOCK_DIAG_BY_FAMILY = 20
_DUMP_REQUEST = 0x301  # NLM_F_REQUEST | NLM_F_DUMP
_NLMSG_ERROR, _NLMSG_DONE = 2, 3
_LISTENING = 1 << 10
_STATES = _LISTENING | 1 << 13
_IPPROTO_TCP = 6


def holding_sockets(domain_id: int) -> frozenset[int] | None:
    """The inodes of the TCP sockets bound to 32768+ID (IPv4 and IPv6); None: cannot tell.

    A socket bound without listen(), as upstream's and colcon's coordinators hold it, is
    in no /proc/net/tcp table: only sock_diag's dump of bound-only sockets shows it, and
    only from Linux 6.8 (older kernels show none: an empty set, no evidence of anyone).
    """
    return _holders(PORT_BASE + domain_id, _STATES)


def listening_sockets(domain_id: int) -> frozenset[int] | None:
    """The inodes of the TCP sockets listening on 32768+ID, which every kernel shows.

    No coordinator listens: a listener holding the port is visibly someone else.
    """
    return _holders(PORT_BASE + domain_id, _LISTENING)


#: The probe's answer, once asked (:func:`shows_bound_sockets`).
_bound_shown: bool | None = None


def shows_bound_sockets() -> bool:
    """Whether this kernel's dump shows a socket bound without listen() (Linux 6.8+).

    Probed once, by binding one (a free port) and looking for its inode; asked only
    where the answer explains a refusal, never on a test's way in.
    """
    global _bound_shown  # one probe per process
    if _bound_shown is None:
        import os  # only here: not on every test's path

        probe = _socket.socket(_socket.AF_INET, _socket.SOCK_STREAM)
        try:
            probe.bind(("127.0.0.1", 0))
            found = _holders(probe.getsockname()[1], _STATES)
            _bound_shown = found is not None and os.fstat(probe.fileno()).st_ino in found
        except OSError:
            _bound_shown = False
        finally:
            probe.close()
    return _bound_shown


def _holders(port: int, states: int) -> frozenset[int] | None:
    """The inodes of the TCP sockets on ``port`` in ``states``, both families; None: cannot tell."""
    import struct  # only here: not on every test's path

    found: set[int] = set()
    try:
        for family in (_socket.AF_INET, _socket.AF_INET6):
            found.update(_dump(family, port, states))
    except (OSError, struct.error):
        return None
    return frozenset(found)


def _dump(family: int, port: int, states: int) -> list[int]:
    """One family's dump, read to its end: the inodes of sockets on ``port``."""
    import struct as _struct  # only here: not on every test's path

    request = _struct.pack("=BBBBI", family, _IPPROTO_TCP, 0, 0, states) + bytes(48)
    header = _struct.pack("=IHHII", 16 + len(request), _SOCK_DIAG_BY_FAMILY, _DUMP_REQUEST, 1, 0)
    inodes: list[int] = []
    sock = _socket.socket(_socket.AF_NETLINK, _socket.SOCK_DGRAM, _NETLINK_SOCK_DIAG)
    try:
        sock.sendto(header + request, (0, 0))
        while True:
            data = sock.recv(65536)
            offset = 0
            while offset + 16 <= len(data):
                length, kind = _struct.unpack_from("=IH", data, offset)
                if kind == _NLMSG_DONE:
                    return inodes
                if kind == _NLMSG_ERROR or length < 16:
                    raise OSError("sock_diag refused the dump")
                # inet_diag_msg: family, state, timer, retrans, then the socket's ID
                # (source port first, big-endian), ..., its inode at byte 68.
                message = offset + 16
                if _struct.unpack_from(">H", data, message + 4)[0] == port:
                    inodes.append(_struct.unpack_from("=I", data, message + 68)[0])
                offset += (length + 3) & ~3
            if not data:
                return inodes
    finally:
        sock.close()
