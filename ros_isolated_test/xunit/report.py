"""``ros-isolated-test report``: what a tree of result files says, counted from the cases.

Reads canonical and raw producer files alike, through the same reader and normaliser
the runner uses, so the counts are the ones a canonical file of it would carry. A flaky
case (it passed after failing: ``flakyFailure``/``flakyError``) counts as passed and is
listed apart, so a rerun never hides that a test is unstable; a case that failed and was
then not run again is a failure, also listed apart. A folder that cannot be read is an
error, never a quiet gap. Names are shown as ``status`` shows them: a file name cannot
forge a line.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ros_isolated_test.text import display_text
from ros_isolated_test.xunit import normalise, reader
from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE
from ros_isolated_test.xunit.canonical import test_name_of
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


def reports(paths: Iterable[Path]) -> list[FileReport]:
    """A report of each result file under ``paths``, and of each folder it could not read."""
    found: list[FileReport] = []
    for item in result_files(paths):
        if isinstance(item, OSError):
            found.append(unreadable_folder(item))
        elif (report := report_file(item)) is not None:
            found.append(report)
    return found


def result_files(paths: Iterable[Path]) -> Iterator[Path | OSError]:
    """``*.xml`` under each path, in a stable order; hidden folders skipped, as colcon does.

    A folder that cannot be listed (no read or search permission) comes as its error,
    where its files would have come: what it holds may be the one failure.
    """
    for path in paths:
        if path.is_file():
            yield path
            continue
        errors: list[OSError] = []
        for folder, dirs, files in os.walk(path, onerror=errors.append):
            yield from _taken(errors)
            dirs[:] = sorted(name for name in dirs if not name.startswith("."))
            for name in sorted(files):
                if name.endswith(".xml"):
                    yield Path(folder) / name
        yield from _taken(errors)


def _taken(errors: list[OSError]) -> Iterator[OSError]:
    """The walk's errors so far, emptied; a folder gone since it was listed held nothing."""
    found = [error for error in errors if not isinstance(error, FileNotFoundError)]
    errors.clear()
    return iter(found)


def unreadable_folder(error: OSError) -> FileReport:
    """A folder ``report`` cannot list, as one error case naming it and how to fix it."""
    path = Path(error.filename)
    shown = _shown_path(path)
    message = (
        f"Cannot read the result folder {shown}: {error.strerror}; the result files in it "
        "are not counted. Let this user read and enter it (chmod a+rx), or run report as "
        "one who may."
    )
    case = Case.saying(path.name or str(path), "result folder", Outcome.ERROR, message)
    return FileReport(path=path, tests=1, errors=1, failed_cases=[case])


def report_file(path: Path) -> FileReport | None:
    """Counts for one file; None for XML that is not a test result (a ctest Test.xml)."""
    read = reader.read(path)
    if read.root_tag is not None and not read.is_xunit:
        return None
    return counted(path, normalise.cases_from(read, None, test_name_of(path)))


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


def text(reports: list[FileReport], verbose: bool) -> str:
    """The per-file lines of colcon, cases failed then not run, flaky cases, the summary last."""
    lines: list[str] = []
    for item in reports:
        counts = summary_line(item.tests, item.errors, item.failures, item.skipped)
        lines.append(f"{_shown_path(item.path)}: {counts}")
        if verbose:
            for case in item.failed_cases:
                lines.append(f"- {_shown_case(case)} ({case.outcome.value})")
                lines.extend(f"  {line}" for line in _first_lines(case.message))
    not_run = [(item, case) for item in reports for case in item.not_run_again]
    if not_run:
        lines.append("")
        lines.append(
            f"Failed, then not run: {len(not_run)} case(s) failed and no later attempt ran "
            "them (counted as failures):"
        )
        lines.extend(_history(not_run, "then not run", verbose))
    flaky = [(item, case) for item in reports for case in item.flaky_cases]
    if flaky:
        passed = sum(1 for _, case in flaky if case.outcome is Outcome.PASSED)
        said = [f"{passed} case(s) passed after failing"] if passed else []
        if len(flaky) > passed:
            said.append(f"{len(flaky) - passed} case(s) skipped after failing")
        lines.append("")
        lines.append(f"Flaky: {', '.join(said)} (not counted as failures):")
        lines.extend(_history(flaky, "", verbose))
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
            "failed_then_not_run": len(item.not_run_again),
            "failed_cases": [
                {
                    "classname": case.classname,
                    "name": case.name,
                    "outcome": case.outcome.value,
                    "message": case.message,
                    "failed_then_not_run": case.type == NOT_RUN_AGAIN_TYPE,
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


def _history(cases: list[tuple[FileReport, Case]], then: str, verbose: bool) -> list[str]:
    """One line per case: its failed attempts, what came after, its file; ``-v``: each one."""
    lines: list[str] = []
    for item, case in cases:
        after = then or ("" if case.outcome is Outcome.PASSED else f"then {case.outcome.value}")
        history = ", ".join(filter(None, (f"{len(case.attempts)} failed attempt(s)", after)))
        lines.append(f"- {_shown_case(case)} ({history}) in {_shown_path(item.path)}")
        if verbose:
            for attempt in case.attempts:
                lines.append(f"  {attempt.kind}: {_first_lines(attempt.message)[0]}")
    return lines


def _shown_path(path: Path) -> str:
    """``path`` on one line, every control character and undecodable byte escaped, uncut."""
    text = str(path)
    return display_text(text, len(text))


def _shown_case(case: Case) -> str:
    """A case's class and name, each on one line as :func:`_shown_path` shows a path."""
    return f"{display_text(case.classname)} {display_text(case.name)}"


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
