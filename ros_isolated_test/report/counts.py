"""The counts of one result file and of a tree, from the cases themselves: they add up.

Each case counts once, by its final outcome: passed, flaky (it passed after failing:
``flakyFailure``/``flakyError``), failure, error or skipped, so ``tests`` is always their
sum and none is ever negative. Two parts are counted apart besides: a failure that
failed and was then not run again (``failed_then_not_run``, still a failure: it never
passed) and a skip that came after failing (``skipped_after_failing``, still a skip:
it never passed either, but a rerun must not hide that it failed). A flaky case is not
a failure, yet it is listed apart so a rerun never hides that a test is unstable.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE
from ros_isolated_test.xunit.model import Case, Outcome

#: The counts that add up to ``tests``, in the order the page shows them.
PARTS = ("passed", "failures", "errors", "flaky", "skipped")
#: Every count, as ``report --json`` names it.
KEYS = ("tests", *PARTS, "failed_then_not_run", "skipped_after_failing")


@dataclass
class FileReport:
    """The counts of one result file (or of a folder that could not be read)."""

    path: Path
    tests: int = 0
    passed: int = 0
    failures: int = 0
    errors: int = 0
    flaky: int = 0
    skipped: int = 0
    #: Failures that failed in an attempt and were in no later one: never passed.
    failed_then_not_run: int = 0
    #: Skips that failed in an earlier attempt.
    skipped_after_failing: int = 0

    @property
    def failed(self) -> bool:
        """Whether anything in the file failed or errored."""
        return bool(self.errors or self.failures)

    def add(self, case: Case) -> None:
        """Count ``case`` once, by its final outcome (and as a part, when it is one)."""
        self.tests += 1
        if case.outcome is Outcome.ERROR:
            self.errors += 1
        elif case.outcome is Outcome.FAILURE:
            self.failures += 1
        elif case.outcome is Outcome.SKIPPED:
            self.skipped += 1
        elif case.flaky:
            self.flaky += 1
        else:
            self.passed += 1
        if not_run_again(case):
            self.failed_then_not_run += 1
        elif skipped_after_failing(case):
            self.skipped_after_failing += 1

    def include(self, other: FileReport) -> None:
        """Add another file's counts: a tree's total is kept as its files go by."""
        for key in KEYS:
            setattr(self, key, getattr(self, key) + getattr(other, key))

    def as_dict(self) -> dict[str, int]:
        """Every count by its name (:data:`KEYS`)."""
        return {key: getattr(self, key) for key in KEYS}


def not_run_again(case: Case) -> bool:
    """A failure that failed in an attempt and that no later attempt ran: it never passed."""
    return case.outcome.failed and case.type == NOT_RUN_AGAIN_TYPE


def skipped_after_failing(case: Case) -> bool:
    """A skip with failed attempts before it (a rerun's, or a case the last attempt lacked)."""
    return case.outcome is Outcome.SKIPPED and bool(case.attempts)


def listed_as_flaky(case: Case) -> bool:
    """Whether a case goes with the flaky ones: not a failure, but it failed before."""
    return case.flaky or skipped_after_failing(case)


def counted(path: Path, cases: list[Case]) -> FileReport:
    """The counts of one file's canonical ``cases``."""
    report = FileReport(path=path)
    for case in cases:
        report.add(case)
    return report


def summary_line(tests: int, errors: int, failures: int, skipped: int) -> str:
    """The counts in colcon test-result's words."""
    return f"{tests} tests, {errors} errors, {failures} failures, {skipped} skipped"
