"""``ros-isolated-test report``'s printed words: colcon's line per file, the summary last.

Failed-then-not-run and flaky cases are listed apart after the files, with their failed
attempts under ``--verbose``; ``--json`` says the same with every failed and flaky case.
A split's merged trees (``shards``) add the shares found and what is wrong with them.
Names are shown as ``status`` shows them: a file name cannot forge a line.

Written in bounded memory however many cases fail: each file's lines (or JSON row) and
its cases for the lists after the files go to spools (temporary files) as it is read,
and only the counts are kept; :meth:`TextReport.write` copies the spools out in order.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

from ros_isolated_test.report.counts import (
    FileReport,
    listed_as_flaky,
    not_run_again,
    summary_line,
)
from ros_isolated_test.report.shard import Split
from ros_isolated_test.report.spool import Spool
from ros_isolated_test.report.tree import FileRead
from ros_isolated_test.text import display_text
from ros_isolated_test.xunit.model import Case, Outcome

#: Lines of a message ``--verbose`` shows.
MESSAGE_LINES = 20


class TextReport:
    """What ``report`` prints (text, or JSON with ``as_json``), gathered file by file."""

    def __init__(self, verbose: bool = False, as_json: bool = False) -> None:
        self.verbose = verbose
        self.as_json = as_json
        #: Every file's counts, summed.
        self.total = FileReport(Path())
        self._files = Spool()
        self._not_run = Spool()
        self._flaky = Spool()
        self._rows = 0
        #: What the trees say of a split, when the caller gathers it (said last).
        self.split: Split | None = None

    def __enter__(self) -> TextReport:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        for spool in (self._files, self._not_run, self._flaky):
            spool.close()

    def add(self, item: FileRead) -> None:
        """One file read: its counts summed, its lines spooled, its cases forgotten."""
        report = item.report
        self.total.include(report)
        if self.as_json:
            self._add_row(item)
            return
        counts = summary_line(report.tests, report.errors, report.failures, report.skipped)
        self._files.write(f"{_shown_path(report.path)}: {counts}\n")
        for case in item.cases:
            if case.outcome.failed and self.verbose:
                self._files.write(f"- {_shown_case(case)} ({case.outcome.value})\n")
                self._files.write("".join(f"  {line}\n" for line in _first_lines(case.message)))
            if not_run_again(case):
                self._history(self._not_run, case, report.path, "then not run")
            elif listed_as_flaky(case):
                after = "" if case.outcome is Outcome.PASSED else f"then {case.outcome.value}"
                self._history(self._flaky, case, report.path, after)

    def _history(self, spool: Spool, case: Case, path: Path, after: str) -> None:
        """One line for a case: its failed attempts, what came after, its file; ``-v``: each."""
        history = ", ".join(filter(None, (f"{len(case.attempts)} failed attempt(s)", after)))
        spool.write(f"- {_shown_case(case)} ({history}) in {_shown_path(path)}\n")
        if self.verbose:
            for attempt in case.attempts:
                spool.write(f"  {attempt.kind}: {_first_lines(attempt.message)[0]}\n")

    def _add_row(self, item: FileRead) -> None:
        """The file's JSON object, indented as a member of the ``files`` list."""
        row = {
            "path": str(item.path),
            **item.report.as_dict(),
            "failed_cases": [
                {
                    "classname": case.classname,
                    "name": case.name,
                    "outcome": case.outcome.value,
                    "message": case.message,
                    "failed_then_not_run": not_run_again(case),
                    "earlier_failures": _earlier(case),
                }
                for case in item.cases
                if case.outcome.failed
            ],
            "flaky_cases": [
                {
                    "classname": case.classname,
                    "name": case.name,
                    "outcome": case.outcome.value,
                    "earlier_failures": _earlier(case),
                }
                for case in item.cases
                if listed_as_flaky(case)
            ],
        }
        text = json.dumps(row, indent=2).replace("\n", "\n    ")
        self._files.write(f"{',' if self._rows else ''}\n    {text}")
        self._rows += 1

    def write(self, put: Callable[[str], object]) -> None:
        """Everything, in order, to ``put`` in pieces of bounded size."""
        if self.as_json:
            put('{\n  "files": [')
            self._files.copy_text(put)
            totals = json.dumps(self.total.as_dict(), indent=2).replace("\n", "\n  ")
            put(f'{chr(10) + "  " if self._rows else ""}],\n  "total": {totals}')
            put(f"{self._json_split()}\n}}\n")
            return
        self._files.copy_text(put)
        total = self.total
        if total.failed_then_not_run:
            put(
                f"\nFailed, then not run: {total.failed_then_not_run} case(s) failed and no "
                "later attempt ran them (counted as failures):\n"
            )
            self._not_run.copy_text(put)
        if total.flaky or total.skipped_after_failing:
            said = [f"{total.flaky} case(s) passed after failing"] if total.flaky else []
            if total.skipped_after_failing:
                said.append(f"{total.skipped_after_failing} case(s) skipped after failing")
            put(f"\nFlaky: {', '.join(said)} (not counted as failures):\n")
            self._flaky.copy_text(put)
        summary = summary_line(total.tests, total.errors, total.failures, total.skipped)
        put(f"\nSummary: {summary}\n")
        self._write_split(put)

    def _json_split(self) -> str:
        """The ``shards`` member of ``--json``: the shares found and the split's problems."""
        split = self.split
        if split is None or not split.is_split:
            return ""
        shares = [
            {"shard": share, "plan": plan, "hosts": hosts} for share, plan, hosts in split.shares()
        ]
        said = json.dumps({"found": shares, "problems": split.problems}, indent=2)
        return ',\n  "shards": ' + said.replace("\n", "\n  ")

    def _write_split(self, put: Callable[[str], object]) -> None:
        """The shares found, then each problem of the split: the summary may be short."""
        split = self.split
        if split is None or not split.is_split:
            return
        shares = ", ".join(
            f"{share} (plan {plan})" if index == 0 or plan != found[index - 1][1] else share
            for found in [split.shares()]
            for index, (share, plan, _hosts) in enumerate(found)
        )
        problems = split.problems
        put(f"Shards: {shares or 'none'}\n")
        if problems:
            put(f"The split's results are incomplete ({len(problems)} problem(s)):\n")
            put("".join(f"- {line}\n" for line in problems))


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
    return (message or "(no message)").splitlines()[:MESSAGE_LINES] or ["(no message)"]
