"""The TCP port that upstream's ``domain_coordinator`` uses to claim a domain ID.

Upstream claims ID N by binding TCP port 32768+N. Binding the same port while we hold
N keeps upstream's runner off our ID, and failing to bind it tells us upstream (or
another program) has N, so both coordinators can share one machine.
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
