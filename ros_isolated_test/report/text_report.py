"""``ros-isolated-test report``'s printed words: colcon's line per file, the summary last.

Failed-then-not-run and flaky cases are listed apart after the files, with their failed
attempts under ``--verbose``; ``--json`` says the same with every failed and flaky case.
Names are shown as ``status`` shows them: a file name cannot forge a line.
"""

from __future__ import annotations

import json
from pathlib import Path

from ros_isolated_test.report.counts import FileReport, summary_line, totals
from ros_isolated_test.text import display_text
from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE
from ros_isolated_test.xunit.model import Case, Outcome


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
