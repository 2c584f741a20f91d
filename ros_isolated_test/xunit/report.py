"""``ros-isolated-test report``: what a tree of result files says, counted from the cases.

Reads canonical and raw producer files alike, through the same reader and normaliser
the runner uses, so the counts are the ones a canonical file of it would carry.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ros_isolated_test.runner.request import test_name_of
from ros_isolated_test.xunit import normalise, reader
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

    @property
    def failed(self) -> bool:
        """Whether anything in the file failed or errored."""
        return bool(self.errors or self.failures)


def result_files(paths: Iterable[Path]) -> Iterator[Path]:
    """``*.xml`` under each path, in a stable order; hidden folders skipped, as colcon does."""
    for path in paths:
        if path.is_file():
            yield path
            continue
        for folder, dirs, files in os.walk(path):
            dirs[:] = sorted(name for name in dirs if not name.startswith("."))
            for name in sorted(files):
                if name.endswith(".xml"):
                    yield Path(folder) / name


def report_file(path: Path) -> FileReport | None:
    """Counts for one file; None for XML that is not a test result (a ctest Test.xml)."""
    read = reader.read(path)
    if read.root_tag is not None and not read.is_xunit:
        return None
    cases = normalise.cases_from(read, None, test_name_of(path))
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
    return report


def summary_line(tests: int, errors: int, failures: int, skipped: int) -> str:
    """The counts in colcon test-result's words."""
    return f"{tests} tests, {errors} errors, {failures} failures, {skipped} skipped"
