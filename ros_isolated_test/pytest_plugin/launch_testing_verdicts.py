"""What ``unittest`` recorded for a launch's cases, read as one verdict per case.

Apart from launch_testing_cases.py, which runs the launch and reports its cases as pytest
items: reading a result knows nothing of pytest, only ``unittest``'s records (errors, failures,
skips, expected failures, class and module fixtures) and launch_testing's result types.
Whatever is not as expected raises ``Mismatch``, which launch_testing_cases turns into
its one warning.
"""

from __future__ import annotations

import re
import unittest
from collections.abc import Sequence
from typing import Any

PASSED, SKIPPED, XFAILED, XPASSED, FAILED, ERROR = (
    "passed", "skipped", "xfailed", "xpassed", "failed", "error"
)  # fmt: skip
#: Worse later: a case with several records (subtests) reports its worst.
_RANK = (PASSED, SKIPPED, XFAILED, XPASSED, FAILED, ERROR)
_HOLDER = re.compile(r"^(setUpClass|setUpModule|tearDownClass|tearDownModule) \((.+)\)$")


class Mismatch(Exception):
    """What of launch_testing differs from what this module reads (for the warning)."""


class Verdict:
    """One case's outcome: its kind, its message and its full text (a traceback)."""

    def __init__(self, kind: str, message: str = "", text: str = "") -> None:
        self.kind = kind
        self.message = message
        self.text = text

    def worse(self, other: Verdict) -> Verdict:
        """The worse of the two, the texts of both kept (subtests fail one case)."""
        first, second = (self, other) if _RANK.index(self.kind) >= _RANK.index(other.kind) else (
            other, self)  # fmt: skip
        text = "\n".join(part for part in (first.text, second.text) if part)
        return Verdict(first.kind, first.message, text)


def as_one(result: Any) -> Verdict:
    """A run's result read as launch_testing's own item reads it: passed or not."""
    succeeded = getattr(result, "wasSuccessful", None)
    if callable(succeeded) and succeeded():
        return Verdict(PASSED)
    records = [*getattr(result, "errors", []), *getattr(result, "failures", [])]
    text = texts(records) if records else f"launch_testing's result: {result!r}"
    return Verdict(FAILED, "some test cases have failed", text)


def texts(entries: Sequence[tuple[Any, str]]) -> str:
    """The texts of several records (unittest's), each under its case's name when more than one."""
    if len(entries) == 1:
        return str(entries[0][1])
    return "\n".join(f"{test}:\n{text}" for test, text in entries)


def fail_result_type() -> type[Any]:
    """launch_testing's result for a launch that stopped early (checked at collection)."""
    import importlib

    try:
        found = getattr(importlib.import_module("launch_testing.test_result"), "FailResult", None)
    except ImportError:
        found = None
    if not isinstance(found, type):
        raise Mismatch("launch_testing.test_result.FailResult is missing")
    return found


def read(
    cases: Sequence[unittest.TestCase], result: Any
) -> tuple[list[Verdict], dict[int, list[str]]]:
    """What ``unittest`` recorded for each of a run's ``cases``, by their position."""
    missing = [name for name in ("testCases", "errors", "failures", "skipped")
               if not hasattr(result, name)]  # fmt: skip
    if missing:
        raise Mismatch(f"its test result has no {', '.join(missing)}")
    where = {id(case): i for i, case in enumerate(cases)}
    ran = {where[id(case)] for case in result.testCases if id(case) in where}
    found: dict[int, Verdict] = {}
    loose: list[tuple[str, str, str]] = []  # (kind, description, text): setUpClass, ...

    def record(test: object, verdict: Verdict) -> None:
        index = where.get(id(test), where.get(id(getattr(test, "test_case", None))))
        if index is None:
            loose.append((verdict.kind, str(test), verdict.text))
        else:
            found[index] = found[index].worse(verdict) if index in found else verdict

    for kind, entries in ((ERROR, result.errors), (FAILED, result.failures)):
        for test, text in entries:
            record(test, Verdict(kind, message(text), text))
    for test, reason in result.skipped:
        record(test, Verdict(SKIPPED, reason))
    for test, text in getattr(result, "expectedFailures", []):
        record(test, Verdict(XFAILED, message(text) or "expected failure", text))
    for test in getattr(result, "unexpectedSuccesses", []):
        record(test, Verdict(XPASSED, "unexpected success: marked expectedFailure, it passed"))
    after: dict[int, list[str]] = {}
    for kind, description, text in loose:
        owned = _owned(cases, description)
        not_run = [i for i in owned if i not in ran and i not in found]
        for i in not_run:
            found[i] = Verdict(kind, f"{description}: {message(text) or text}", text)
        if not not_run and kind == ERROR and owned:
            after.setdefault(owned[-1], []).append(f"{description}:\n{text}")
    verdicts = []
    for i in range(len(cases)):
        if i in found:
            verdicts.append(found[i])
        elif i in ran:
            verdicts.append(Verdict(PASSED))
        else:
            verdicts.append(Verdict(ERROR, "launch_testing recorded no result for this case"))
    return verdicts, after


def _owned(cases: Sequence[unittest.TestCase], description: str) -> list[int]:
    """The cases a class or module fixture's record is about (all of them when unsure)."""
    match = _HOLDER.match(description)
    if match is not None:
        scope = match.group(2)
        owned = [i for i, case in enumerate(cases) if case.id().startswith(f"{scope}.")]
        if owned:
            return owned
    return list(range(len(cases)))


def message(text: str) -> str:
    """The exception a formatted traceback ends with (all of ``text`` if it is none)."""
    lines = text.rstrip().splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith("Traceback (")]
    if not starts:
        return text.strip()
    rest = lines[starts[-1] + 1 :]
    while rest and rest[0].startswith(" "):
        rest = rest[1:]
    return "\n".join(rest).strip() or text.strip()
