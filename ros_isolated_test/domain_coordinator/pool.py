"""Which domain IDs the coordinator may hand out: ``ROS_ISOLATED_TEST_DOMAINS``.

Without it, the default 1-101 less the IDs whose DDS ports fall in the ephemeral port range.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence

from ros_isolated_test import names, not_run

POOL_ENV = names.DOMAINS
DEFAULT_SPEC = "1-101"
#: Fast DDS computes ports from the ID; from 233 up node creation kills the process.
HIGHEST_VALID_ID = 232


def _number(text: str) -> int | None:
    """Plain ASCII digits only: int() would also take "1_0" and non-ASCII digits."""
    text = text.strip()
    return int(text) if text.isascii() and text.isdigit() else None


class PoolSpecError(not_run.NotRun, ValueError):
    """The pool spec cannot be used; the message says why and how to fix it."""


def parse_pool(spec: str) -> tuple[int, ...]:
    """Parse ``1-101`` or ``1-50,215-232`` into the IDs it names, in order, without repeats.

    Domain 0 is refused: it is where every process without ROS_DOMAIN_ID talks, so a
    test on it is not isolated from anything.
    """
    ids: list[int] = []
    seen: set[int] = set()
    items = [item.strip() for item in spec.split(",")]
    if not spec.strip() or any(not item for item in items):
        raise PoolSpecError(f"empty entry in domain pool {spec!r}")
    for item in items:
        first, dash, last = item.partition("-")
        low = _number(first)
        high = _number(last) if dash else low
        if low is None or high is None:
            raise PoolSpecError(
                f"{item!r} in domain pool {spec!r} is not an ID or a range like 1-101"
            )
        if low > high:
            raise PoolSpecError(f"range {item!r} in domain pool {spec!r} runs backwards")
        if low < 1 or high > HIGHEST_VALID_ID:
            raise PoolSpecError(
                f"{item!r} in domain pool {spec!r} is outside 1-{HIGHEST_VALID_ID}"
                " (0 is every un-isolated process's domain; ROS allows at most 232)"
            )
        for domain_id in range(low, high + 1):
            if domain_id not in seen:
                seen.add(domain_id)
                ids.append(domain_id)
    return tuple(ids)


# -- the ephemeral port range --------------------------------------------------------------
#
# DDS binds fixed UDP ports computed from the ID; the kernel hands out ephemeral ports
# (any program's outgoing connection, any bind to port 0) from net.ipv4.ip_local_port_range.
# Where the two overlap, another program can hold a port a test's participant needs, and
# discovery on that ID breaks for reasons nobody can see from the test. The setting is
# per network namespace (containers, tuned hosts), so it is read where the runner runs.

#: Linux's default ``net.ipv4.ip_local_port_range``, assumed where it cannot be read.
LINUX_DEFAULT_PORT_RANGE = (32768, 60999)
PORT_RANGE_FILE = "/proc/sys/net/ipv4/ip_local_port_range"
PORT_RANGE_SYSCTL = "net.ipv4.ip_local_port_range"
#: Ports of one domain above its first (7400 + 250*ID): multicast discovery at +0, the
#: metatraffic at +1, then unicast pairs at +10/+11 + 2*i for participant i on the host.
#: ROS's LOCALHOST range announces participants 0-31 only, so the last port a domain
#: can need is 7411 + 250*ID + 2*31, that is +73.
DDS_PORT_SPAN = 73


def dds_ports(domain_id: int) -> tuple[int, int]:
    """The first and last UDP port DDS uses on ``domain_id`` (see :data:`DDS_PORT_SPAN`)."""
    first = 7400 + 250 * domain_id
    return first, first + DDS_PORT_SPAN


def in_port_range(domain_id: int, port_range: tuple[int, int]) -> bool:
    """Whether any DDS port of ``domain_id`` lies in ``port_range`` (inclusive, as Linux)."""
    first, last = dds_ports(domain_id)
    low, high = port_range
    return first <= high and last >= low


def parse_port_range(text: str) -> tuple[int, int] | None:
    """The two ports of the sysctl's text (two numbers), None when garbled."""
    numbers = [_number(field) for field in text.split()]
    if len(numbers) != 2 or numbers[0] is None or numbers[1] is None:
        return None
    low, high = numbers[0], numbers[1]
    return (low, high) if 0 < low <= high <= 65535 else None


def read_port_range(path: str = PORT_RANGE_FILE) -> tuple[int, int]:
    """The ephemeral port range of this network namespace; Linux's default when unreadable.

    No /proc (another OS, a sandbox) or a garbled file says nothing we could act on:
    the default is what a kernel that hides it most likely uses, and keeps 1-101.
    """
    try:
        with open(path, "rb") as handle:
            text = handle.read(64).decode("ascii", "replace")
    except OSError:
        return LINUX_DEFAULT_PORT_RANGE
    return parse_port_range(text) or LINUX_DEFAULT_PORT_RANGE


def id_ranges(ids: Iterable[int]) -> str:
    """``102-110, 150`` for those IDs: consecutive ones compressed, in ascending order."""
    spans: list[list[int]] = []
    for domain_id in sorted(set(ids)):
        if spans and domain_id == spans[-1][1] + 1:
            spans[-1][1] = domain_id
        else:
            spans.append([domain_id, domain_id])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)


def _range_text(port_range: tuple[int, int]) -> str:
    low, high = port_range
    return f"this host's ephemeral port range {low}-{high} ({PORT_RANGE_SYSCTL})"


def _clear_ids(port_range: tuple[int, int]) -> str:
    """Every valid ID clear of ``port_range``: what a user may put in the variable."""
    return id_ranges(i for i in range(1, HIGHEST_VALID_ID + 1) if not in_port_range(i, port_range))


def _ids(ids: Sequence[int]) -> str:
    return f"IDs {id_ranges(ids)}" if len(ids) > 1 else f"ID {ids[0]}"


def default_pool(port_range: tuple[int, int]) -> tuple[tuple[int, ...], tuple[str, ...]]:
    """The default pool's IDs clear of ``port_range``, and the line saying what was left out.

    Never more than the default's own IDs: on a host with Linux's default range nothing
    changes. Raises :class:`PoolSpecError` when no ID is left.
    """
    full = parse_pool(DEFAULT_SPEC)
    kept = tuple(i for i in full if not in_port_range(i, port_range))
    left_out = [i for i in full if i not in kept]
    clear = _clear_ids(port_range)
    if not kept:
        where = f"IDs clear of it ({clear})" if clear else "IDs anyway (none of 1-232 is clear)"
        raise PoolSpecError(
            f"no ID of the default domain pool {DEFAULT_SPEC} is usable: their DDS ports fall "
            f"in {_range_text(port_range)}; set {POOL_ENV} to {where}, or move or narrow the "
            "range"
        )
    if not left_out:
        return kept, ()
    note = (
        f"{_ids(left_out)} left out of the default pool, which is {id_ranges(kept)} here: "
        f"their DDS ports fall in {_range_text(port_range)}; set {POOL_ENV} to choose IDs "
        f"yourself (clear of it: {clear})"
    )
    return kept, (note,)


def explicit_warnings(ids: Sequence[int], port_range: tuple[int, int]) -> tuple[str, ...]:
    """The one-line warning for IDs the user chose whose DDS ports fall in ``port_range``.

    They are used as given: the user may know the range is quiet there.
    """
    clashing = [i for i in ids if in_port_range(i, port_range)]
    if not clashing:
        return ()
    return (
        f"WARNING: {POOL_ENV} names {_ids(clashing)} whose DDS ports fall in "
        f"{_range_text(port_range)}: another program's connection can take such a port and "
        f"break discovery on that ID; used as given (IDs clear of it: "
        f"{_clear_ids(port_range) or 'none'})",
    )


def choose_pool(
    environ: Mapping[str, str] | None = None, port_range: tuple[int, int] | None = None
) -> tuple[tuple[int, ...], tuple[str, ...]]:
    """The pool to hand out and the lines to say about it, given the ephemeral port range.

    ``ROS_ISOLATED_TEST_DOMAINS`` when set (with a warning for IDs in the range), else
    the default 1-101 without its IDs in the range. ``port_range`` None: read this
    network namespace's. Raises :class:`PoolSpecError` (one line, the fix in it).
    """
    environ = os.environ if environ is None else environ
    spec = environ.get(POOL_ENV, "").strip()
    if not spec:
        return default_pool(port_range or read_port_range())
    try:
        ids = parse_pool(spec)
    except PoolSpecError as error:
        raise PoolSpecError(
            f"{POOL_ENV}: {error}; set it to ranges like '1-101' or '1-50,215-232', or unset it"
        ) from None
    return ids, explicit_warnings(ids, port_range or read_port_range())


def pool_from_env(
    environ: Mapping[str, str] | None = None, port_range: tuple[int, int] | None = None
) -> tuple[int, ...]:
    """The pool of :func:`choose_pool`, without its notes."""
    return choose_pool(environ, port_range)[0]
