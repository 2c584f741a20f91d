"""The plan as ``ros-isolated-test shard --plan`` shows it: text for people, JSON for tools.

What a user needs to pick N before paying for machines: each share's tests and expected
time, and the lower bound no split can beat (the larger of the total over N and the
longest test), with how far the longest share is above it. Identical on every machine
and Python for the same input: ordered by share, then longest first, then identity, and
every figure computed from whole microseconds.
"""

from __future__ import annotations

import json

from ros_isolated_test.shard.durations import MICROS
from ros_isolated_test.shard.plan import QUICK, Placed, Plan
from ros_isolated_test.text import display_text

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["Summary", "as_json", "seconds", "summary", "text"]


class Summary:
    """The figures of a plan over a set of tests, in whole microseconds."""

    __slots__ = (
        "best_possible",
        "gone",
        "listing",
        "loads",
        "longest_test",
        "lower_bound",
        "total",
    )

    def __init__(self, plan: Plan, found: Iterable[str] | None) -> None:
        found = None if found is None else set(found)
        self.listing = plan.shares(found or ())
        self.loads = [sum(test.micros for test in tests) for tests in self.listing]
        self.total = sum(self.loads)
        self.longest_test = max(
            (test.micros for tests in self.listing for test in tests), default=0
        )
        #: The lower bound: the larger of the total over N and the longest test.
        self.lower_bound = max(-(-self.total // plan.total), self.longest_test)
        # Of the N+1 longest tests two share a machine: no split beats the two shortest.
        weights = sorted((test.micros for tests in self.listing for test in tests), reverse=True)
        pair = weights[plan.total - 1] + weights[plan.total] if len(weights) > plan.total else 0
        #: No split can end sooner: the lower bound, or that pair where it is larger.
        self.best_possible = max(self.lower_bound, pair)
        #: The file's tests not among ``found`` (removed since, or not run there); none
        #: when no tests were found anywhere to compare with.
        self.gone = (
            []
            if not found or plan.durations is None
            else sorted(key for key in plan.durations.micros if key not in found)
        )

    @property
    def unknown(self) -> int:
        """Tests placed by their hash: not in the durations file."""
        return sum(1 for tests in self.listing for test in tests if not test.known)


def summary(plan: Plan, found: Iterable[str] | None = None) -> Summary:
    """The figures of ``plan`` with the tests ``found`` in result trees (None: none given)."""
    return Summary(plan, found)


def seconds(us: int) -> str:
    """Microseconds to show: two decimals of a second below 10 s, one above.

    Below 10 ms (not 0), milliseconds to the microsecond: a 0.3 ms test is no ``0.00 s``.
    """
    if 0 < us < 10_000:
        return f"{us // 1000}.{us % 1000:03d} ms"
    hundredths = (us + 5000) // 10_000
    if hundredths < 1000:
        return f"{hundredths // 100}.{hundredths % 100:02d} s"
    tenths = (us + 50_000) // 100_000
    return f"{tenths // 10}.{tenths % 10} s"


def _tests(count: int) -> str:
    return f"{count} test" if count == 1 else f"{count} tests"


def _ratio(value: int, bound: int) -> str:
    """``value / bound`` to two decimals, from integers."""
    if bound == 0:
        return "1.00"
    hundredths = (value * 100 + bound // 2) // bound
    return f"{hundredths // 100}.{hundredths % 100:02d}"


def _test_line(test: Placed, width: int, by_count: bool) -> str:
    name = display_text(test.identity)
    if by_count:
        return f"  {name}"
    note = "" if test.known else "  (new: not in the durations file, weighed as the median)"
    return f"  {seconds(test.micros).rjust(width)}  {name}{note}"


def text(plan: Plan, found: Iterable[str] | None = None, source: str | None = None) -> str:
    """The plan for people: a header with the figures, then each share and its tests."""
    figures = summary(plan, found)
    count = sum(len(tests) for tests in figures.listing)
    total = plan.total
    if plan.by_count:
        lines = [
            f"Plan for {total} shares by count (no durations): {_tests(count)}, each share "
            "drawn from the hash of the test's identity"
        ]
    else:
        durations = plan.durations
        assert durations is not None
        named = f" {display_text(source)}" if source else ""
        longest_share = max(figures.loads)
        lines = [
            f"Plan for {total} shares from the durations file{named} (plan "
            f"{durations.fingerprint}, {_tests(len(durations))}): {_tests(count)}, "
            f"{figures.unknown} not in the file (weighed as its median, {seconds(plan.median)})",
            f"Expected: {seconds(figures.total)} in all; lower bound "
            f"{seconds(figures.lower_bound)} (the larger of the total / {total} and the longest "
            f"test, {seconds(figures.longest_test)}); the longest share "
            f"{seconds(longest_share)}, {_ratio(longest_share, figures.lower_bound)} x the "
            "lower bound",
        ]
        if figures.best_possible > figures.lower_bound:
            lines.append(
                f"No split into {total} does better than {seconds(figures.best_possible)}: two of "
                f"the {total + 1} longest tests must share a machine (the longest share is "
                f"{_ratio(longest_share, figures.best_possible)} x that)"
            )
    quick = sum(
        1 for tests in figures.listing for test in tests if test.known and test.micros < QUICK
    )
    if quick and not plan.by_count:
        lines.append(
            f"{_tests(quick)} quicker than a millisecond: placed by count (onto the share "
            "with the fewest tests), their time too small to balance by"
        )
    if figures.gone:
        lines.append(
            f"{_tests(len(figures.gone))} of the file not in the trees (removed since, or not "
            "run there): still placed, they make their shares look longer"
        )
    shown = [seconds(test.micros) for tests in figures.listing for test in tests]
    width = max(map(len, shown), default=0)
    for index, tests in enumerate(figures.listing, start=1):
        lines.append("")
        if plan.by_count:
            lines.append(f"Share {index}/{total}: {_tests(len(tests))}")
        else:
            load = seconds(figures.loads[index - 1])
            lines.append(f"Share {index}/{total}: {load} expected, {_tests(len(tests))}")
        lines.extend(_test_line(test, width, plan.by_count) for test in tests)
    return "\n".join(lines) + "\n"


def as_json(plan: Plan, found: Iterable[str] | None = None, source: str | None = None) -> str:
    """The same as :func:`text`, as JSON: seconds as numbers, every test with its share."""
    figures = summary(plan, found)
    by_count = plan.by_count

    def timed(us: int) -> float | None:
        return None if by_count else us / MICROS

    document = {
        "total": plan.total,
        "by": "count" if by_count else "durations",
        "durations_file": None if by_count else source,
        "plan": "count" if plan.durations is None else plan.durations.fingerprint,
        "tests": sum(len(tests) for tests in figures.listing),
        "not_in_durations": figures.unknown,
        "median_seconds": timed(plan.median),
        "total_seconds": timed(figures.total),
        "longest_test_seconds": timed(figures.longest_test),
        "lower_bound_seconds": timed(figures.lower_bound),
        "best_possible_seconds": timed(figures.best_possible),
        "longest_share_seconds": timed(max(figures.loads)),
        "not_in_trees": figures.gone,
        "shares": [
            {
                "share": f"{index}/{plan.total}",
                "expected_seconds": timed(figures.loads[index - 1]),
                "tests": [
                    {"identity": test.identity, "seconds": timed(test.micros), "known": test.known}
                    for test in tests
                ],
            }
            for index, tests in enumerate(figures.listing, start=1)
        ],
    }
    return json.dumps(document, indent=2)
