"""Machine-wide test resources (CPUs, memory, devices): how requests and capacity are written.

A request (``run --resources cpu=2,mem=4G,gpu=1``, ROS_ISOLATED_TEST_RESOURCES) and the
capacity (ROS_ISOLATED_TEST_CAPACITY) share one syntax: comma-separated ``name=amount``.
``cpu`` counts CPUs, ``mem`` bytes (suffixes K, M, G, T: powers of 1024), any other name
counts units of a device or licence. Capacity defaults to the CPUs this process may use,
MemTotal and 1 of anything else (exclusive). Holding them is ``resource_holds``' job.

Plain code, no ``re``: the RUNNER parses a request on every test that asks for one.
"""

from __future__ import annotations

import os

from ros_isolated_test import names, not_run

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Iterable

RESOURCES_ENV = names.RESOURCES
CAPACITY_ENV = names.CAPACITY
CPU = "cpu"
MEM = "mem"
#: Longest resource name: names land in file records and in every status line.
MAX_NAME = 32
#: Most names in one request or capacity: records hold no more.
MAX_NAMES = 16
#: Largest amount of anything (an exabyte of memory): no overflow, no absurd typo.
MAX_AMOUNT = 1 << 60
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
_NAME_START = "abcdefghijklmnopqrstuvwxyz"
_NAME_REST = _NAME_START + "0123456789_-"

__all__ = [
    "CAPACITY_ENV",
    "CPU",
    "MEM",
    "RESOURCES_ENV",
    "ResourceSpecError",
    "capacity_for",
    "default_capacity",
    "describe",
    "parse",
    "show_amount",
]


class ResourceSpecError(not_run.NotRun, ValueError):
    """A request or capacity that cannot be used: one line naming it and the fix."""


def _amount(name: str, text: str, origin: str) -> int:
    """``text`` as a positive whole amount of ``name`` (bytes for mem)."""
    value = text.strip()
    unit = 1
    if name == MEM:
        upper = value.upper()
        for suffix in ("IB", "B"):
            if upper.endswith(suffix) and len(upper) > len(suffix):
                upper = upper[: -len(suffix)]
                break
        if upper[-1:] in _UNITS and upper[-1:]:
            unit = _UNITS[upper[-1]]
            upper = upper[:-1]
        value = upper
    # Checked by length first: int() refuses strings of thousands of digits.
    if not (value.isascii() and value.isdigit() and len(value.lstrip("0")) <= 19):
        example = "4G" if name == MEM else "2"
        raise ResourceSpecError(
            f"{origin}: {name}={text.strip()!r} is not a whole amount; write e.g. "
            f"{name}={example}" + (" (K, M, G, T: powers of 1024)" if name == MEM else "")
        )
    amount = int(value) * unit
    if amount <= 0:
        raise ResourceSpecError(
            f"{origin}: {name}={text.strip()!r} is zero; give a positive amount or leave {name} out"
        )
    if amount > MAX_AMOUNT:
        raise ResourceSpecError(f"{origin}: {name}={text.strip()!r} is too large")
    return amount


def parse(text: str, origin: str) -> dict[str, int]:
    """``name=amount,...`` as {name: amount}; :class:`ResourceSpecError` names ``origin``.

    Empty text is no request. Names are lower-case letters, digits, ``_`` and ``-``
    (they become parts of file records); each at most once.
    """
    amounts: dict[str, int] = {}
    for item in text.split(","):
        if not item.strip():
            continue
        name, equals, value = item.partition("=")
        name = name.strip()
        if not equals or not value.strip():
            raise ResourceSpecError(
                f"{origin}: {item.strip()!r} is not name=amount; write e.g. {CPU}=2,{MEM}=4G,gpu=1"
            )
        if not (
            0 < len(name) <= MAX_NAME
            and name[0] in _NAME_START
            and all(char in _NAME_REST for char in name)
        ):
            raise ResourceSpecError(
                f"{origin}: {name!r} is not a resource name; use lower-case letters, digits, "
                f"'_' and '-', starting with a letter (e.g. {CPU}, {MEM}, gpu)"
            )
        if name in amounts:
            raise ResourceSpecError(f"{origin}: {name} is given twice; give it once")
        amounts[name] = _amount(name, value, origin)
    if len(amounts) > MAX_NAMES:
        raise ResourceSpecError(
            f"{origin}: {len(amounts)} resources named; name at most {MAX_NAMES}"
        )
    return amounts


def _cpus() -> int:
    """The CPUs this process may run on (its affinity), which a container or taskset cuts."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _mem_total() -> int:
    """MemTotal in bytes, from /proc/meminfo (0 when unreadable)."""
    try:
        with open("/proc/meminfo", "rb") as file:
            for line in file:
                if line.startswith(b"MemTotal:"):
                    words = line.split()
                    return int(words[1]) * 1024 if len(words) >= 2 else 0
    except (OSError, ValueError):
        pass
    return 0


def default_capacity(name: str) -> int:
    """What the machine has of ``name`` when the capacity does not say: any other name is 1."""
    if name == CPU:
        return _cpus()
    if name == MEM:
        return _mem_total() or MAX_AMOUNT
    return 1


def capacity_for(names: Iterable[str], capacity: dict[str, int]) -> dict[str, int]:
    """The capacity of each of ``names``: as set, else the default."""
    return {name: capacity[name] if name in capacity else default_capacity(name) for name in names}


def show_amount(name: str, amount: int) -> str:
    """An amount as a person writes it: mem in the largest unit that divides it."""
    if name == MEM:
        for suffix in ("T", "G", "M", "K"):
            unit = _UNITS[suffix]
            if amount % unit == 0:
                return f"{amount // unit}{suffix}"
    return str(amount)


def describe(amounts: dict[str, int]) -> str:
    """``cpu=2,mem=4G,gpu=1``: the canonical text of a request or a capacity, names sorted."""
    return ",".join(f"{name}={show_amount(name, amounts[name])}" for name in sorted(amounts))
