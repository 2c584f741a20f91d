"""``ros-isolated-test report``: what a tree of result files says, counted from the cases.

Reads canonical and raw producer files alike, through the same reader and normaliser
the runner uses, so the counts are the ones a canonical file of it would carry. A flaky
case (it passed after failing: ``flakyFailure``/``flakyError``) counts as passed and is
listed apart, so a rerun never hides that a test is unstable.
"""

from __future__ import annotations

import json
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
    flaky_cases: list[Case] = field(default_factory=list)

    @property
    def flaky(self) -> int:
        """Cases that passed (or were skipped) after failing: not failures."""
        return len(self.flaky_cases)

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
        elif case.flaky:
            report.flaky_cases.append(case)
    return report


def totals(reports: list[FileReport]) -> dict[str, int]:
    """The counts of all files; ``flaky`` apart, as it is not an outcome of its own."""
    keys = ("tests", "errors", "failures", "skipped", "flaky")
    return {key: sum(getattr(item, key) for item in reports) for key in keys}


def text(reports: list[FileReport], verbose: bool) -> str:
    """The per-file lines of colcon, the flaky cases, and the summary as the last line."""
    lines: list[str] = []
    for item in reports:
        lines.append(
            f"{item.path}: {summary_line(item.tests, item.errors, item.failures, item.skipped)}"
        )
        if verbose:
            for case in item.failed_cases:
                lines.append(f"- {case.classname} {case.name} ({case.outcome.value})")
                lines.extend(f"  {line}" for line in _first_lines(case.message))
    flaky = [(item, case) for item in reports for case in item.flaky_cases]
    if flaky:
        lines.append("")
        lines.append(f"Flaky: {len(flaky)} case(s) passed after failing (not counted as failures):")
        for item, case in flaky:
            failed = len(case.attempts)
            lines.append(
                f"- {case.classname} {case.name} ({failed} failed attempt(s)) in {item.path}"
            )
            if verbose:
                for attempt in case.attempts:
                    lines.append(f"  {attempt.kind}: {_first_lines(attempt.message)[0]}")
    count = totals(reports)
    summary = summary_line(count["tests"], count["errors"], count["failures"], count["skipped"])
    lines.extend(("", f"Summary: {summary}"))
    return "\n".join(lines) + "\n"


def as_json(reports: list[FileReport]) -> str:
    """The same as :func:`text`, every file's failed and flaky cases included."""
    rows = [
        {
            "path": str(item.path),
            "tests": item.tests,
            "errors": item.errors,
            "failures": item.failures,
            "skipped": item.skipped,
            "flaky": item.flaky,
            "failed_cases": [
                {
                    "classname": case.classname,
                    "name": case.name,
                    "outcome": case.outcome.value,
                    "message": case.message,
                    "earlier_failures": _earlier(case),
                }
                for case in item.failed_cases
            ],
            "flaky_cases": [
                {
                    "classname": case.classname,
                    "name": case.name,
                    "outcome": case.outcome.value,
                    "earlier_failures": _earlier(case),
                }
                for case in item.flaky_cases
            ],
        }
        for item in reports
    ]
    return json.dumps({"files": rows, "total": totals(reports)}, indent=2)


def _earlier(case: Case) -> list[dict[str, str]]:
    """The failed attempts a case's file keeps (``rerun*``/``flaky*``), oldest first."""
    return [
        {"kind": attempt.kind, "type": attempt.type, "message": attempt.message}
        for attempt in case.attempts
    ]


def _first_lines(message: str) -> list[str]:
    return (message or "(no message)").splitlines()[:20] or ["(no message)"]


def summary_line(tests: int, errors: int, failures: int, skipped: int) -> str:
    """The counts in colcon test-result's words."""
    return f"{tests} tests, {errors} errors, {failures} failures, {skipped} skipped"
