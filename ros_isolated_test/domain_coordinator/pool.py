"""Which domain IDs the coordinator may hand out: ``ROS_ISOLATED_TEST_DOMAINS``."""

from __future__ import annotations

import os
from collections.abc import Mapping

POOL_ENV = "ROS_ISOLATED_TEST_DOMAINS"
DEFAULT_SPEC = "1-101"
#: Fast DDS computes ports from the ID; from 233 up node creation kills the process.
HIGHEST_VALID_ID = 232


def _number(text: str) -> int | None:
    """Plain ASCII digits only: int() would also take "1_0" and non-ASCII digits."""
    text = text.strip()
    return int(text) if text.isascii() and text.isdigit() else None


class PoolSpecError(ValueError):
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


def pool_from_env(environ: Mapping[str, str] | None = None) -> tuple[int, ...]:
    """The pool named by ``ROS_ISOLATED_TEST_DOMAINS``, else the default 1-101."""
    environ = os.environ if environ is None else environ
    spec = environ.get(POOL_ENV, "").strip() or DEFAULT_SPEC
    try:
        return parse_pool(spec)
    except PoolSpecError as error:
        raise PoolSpecError(
            f"{POOL_ENV}: {error}; set it to ranges like '1-101' or '1-50,215-232', or unset it"
        ) from None
