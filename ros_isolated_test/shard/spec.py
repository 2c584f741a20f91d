"""A machine's share of a split: ``I/N`` (share I of N), read one way everywhere.

``ROS_ISOLATED_TEST_SHARD=I/N`` in the environment of ``colcon test`` (and the options
``run --shard I/N`` and ``--ros-isolated-test-shard I/N`` of the entry points) name it.
Shares count from 1, as GitLab's ``CI_NODE_INDEX`` does (Kubernetes's
``JOB_COMPLETION_INDEX`` counts from 0: ``$((JOB_COMPLETION_INDEX+1))/N``), up to
``MAX_TOTAL`` shares: more machines than that for one workspace's tests is a typo, and
every share costs its machine a build. Blanks around the value are ignored (a CI
template's trailing newline); none may stand inside it, nor anything but ASCII digits
(``int`` would take ``٣`` and ``1_0``). A blank value is no split at all, like an unset
one: a CI file may define the variable empty outside its parallel jobs, and a runner
passes the share to no test it starts. Anything else is a usage error naming the variable
or option, the value and the fix, in one line: a typo must never run the wrong tests.
"""

from __future__ import annotations

from ros_isolated_test import names, not_run

TYPE_CHECKING = False  # no typing import on a test's path
if TYPE_CHECKING:
    from collections.abc import Mapping

SHARD_ENV = names.SHARD
#: The durations file the split balances by (``shard.durations`` reads it); named here,
#: beside the share, so what only needs the names loads nothing more.
DURATIONS_ENV = names.DURATIONS
#: The most shares one split may have.
MAX_TOTAL = 1000
#: What a value must look like, said in every error.
FORM = "I/N: share I of N, I from 1 to N, N at most 1000 (e.g. 2/4)"

__all__ = [
    "DURATIONS_ENV",
    "FORM",
    "MAX_TOTAL",
    "SHARD_ENV",
    "ShardSettingError",
    "Share",
    "ShareSpecError",
    "named",
    "parse",
    "share_from",
]


class ShardSettingError(not_run.NotRun, ValueError):
    """A setting of the split that cannot be used: one line naming it and the fix."""


class ShareSpecError(ShardSettingError):
    """A share that cannot be used: one line naming where it came from and the fix."""


class Share:
    """Share ``index`` of ``total`` (both from 1), written ``index/total``."""

    __slots__ = ("index", "total")

    def __init__(self, index: int, total: int) -> None:
        if not 1 <= index <= total <= MAX_TOTAL:
            raise ValueError(f"no share {index}/{total}: {FORM}")
        self.index = index
        self.total = total

    def __str__(self) -> str:
        return f"{self.index}/{self.total}"

    def __repr__(self) -> str:
        return f"Share({self.index}, {self.total})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Share):
            return NotImplemented
        return (self.index, self.total) == (other.index, other.total)

    def __hash__(self) -> int:
        return hash((self.index, self.total))


def named(origin: str, value: str) -> str:
    """How an error names a setting and its value: ``VAR=value``, ``--option value``."""
    return f"{origin} {value}" if origin.startswith("-") else f"{origin}={value}"


def _number(digits: str) -> int | None:
    """``digits`` as a number when they are ASCII digits only (at most 9), else None."""
    if not digits or len(digits) > 9 or not (digits.isascii() and digits.isdigit()):
        return None
    return int(digits)


def parse(value: str | None, origin: str = SHARD_ENV) -> Share | None:
    """The share ``value`` names; None when it is unset or blank (no split).

    ``origin`` is the variable or option it came from, named in the error.
    """
    if value is None or not value.strip():
        return None
    said = named(origin, repr(value))
    head, slash, tail = value.strip().partition("/")
    index, total = _number(head), _number(tail)
    if not slash or index is None or total is None:
        raise ShareSpecError(f"{said} is not {FORM}")
    if not 1 <= total <= MAX_TOTAL:
        raise ShareSpecError(f"{said}: N must be from 1 to {MAX_TOTAL}; give {FORM}")
    if index == 0:
        raise ShareSpecError(
            f"{said}: shares count from 1, so I must be from 1 to {total} (a 0-based index "
            f"such as Kubernetes's JOB_COMPLETION_INDEX: $((JOB_COMPLETION_INDEX+1))/{total})"
        )
    if index > total:
        raise ShareSpecError(f"{said}: I must be from 1 to N={total}; give {FORM}")
    return Share(index, total)


def share_from(
    environ: Mapping[str, str], option: str | None = None, origin: str = "--shard"
) -> Share | None:
    """The share an entry point runs: its option's value (from ``origin``) wins over the variable.

    The variable is then not read at all, as with every setting of ours: a bad value
    exported for other commands cannot break a command given its share explicitly.
    """
    if option is not None:
        return parse(option, origin)
    return parse(environ.get(SHARD_ENV), SHARD_ENV)
