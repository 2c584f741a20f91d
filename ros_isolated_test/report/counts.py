"""The counts of one result file and of a tree, from the cases themselves.

A flaky case (it passed after failing: ``flakyFailure``/``flakyError``) counts as
passed and is kept apart, so a rerun never hides that a test is unstable; a case that
failed and was then not run again is a failure, also kept apart.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE
from ros_isolated_test.xunit.model import Case, Outcome


@dataclass
class FileReport:
    """The counts of one result file, and its failing cases."""

    path: Path
    tests: int = 0
    errors: int = 0
    failures: int = 0
    skipped: int = 0
    failed_cases: list[Case] = field(default_factory=list)
    flaky_cases: list[Case] = field(default_factory=list)

    @property
    def flaky(self) -> int:
        """Cases that passed (or were skipped) after failing: not failures."""
        return len(self.flaky_cases)

    @property
    def not_run_again(self) -> list[Case]:
        """Failed cases that failed in an attempt and were not in a later one: no pass."""
        return [case for case in self.failed_cases if case.type == NOT_RUN_AGAIN_TYPE]

    @property
    def failed(self) -> bool:
        """Whether anything in the file failed or errored."""
        return bool(self.errors or self.failures)


def counted(path: Path, cases: list[Case]) -> FileReport:
    """The counts of one file's canonical ``cases``; its failed and flaky ones kept."""
    report = FileReport(path=path, tests=len(cases))
    for case in cases:
        if case.outcome is Outcome.ERROR:
            report.errors += 1
        elif case.outcome is Outcome.FAILURE:
            report.failures += 1
        elif case.outcome is Outcome.SKIPPED:
            report.skipped += 1
        if case.outcome.failed:
            report.failed_cases.append(case)
        elif case.flaky:
            report.flaky_cases.append(case)
    return report


def totals(reports: list[FileReport]) -> dict[str, int]:
    """The counts of all files; ``flaky`` and ``failed_then_not_run`` (failures) apart."""
    keys = ("tests", "errors", "failures", "skipped", "flaky")
    found = {key: sum(getattr(item, key) for item in reports) for key in keys}
    found["failed_then_not_run"] = sum(len(item.not_run_again) for item in reports)
    return found


def summary_line(tests: int, errors: int, failures: int, skipped: int) -> str:
    """The counts in colcon test-result's words."""
    return f"{tests} tests, {errors} errors, {failures} failures, {skipped} skipped"
