"""The report page put together: what it keeps while files are read, then its parts in order.

:class:`Page` is all that is kept while result files are read: the counts, a few
distinct facts per kind (and how many files did not record each), a few of the values
that could not be drawn, one bar per attempt and three spools of case blocks. Once every
file is read, :func:`assemble` streams the page in reading order (the totals first
although they are known last), copying the spools into it. Apart from the reading of
each file (``html_report``) so that the page's layout reads in one place.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable
from html import escape
from pathlib import Path
from typing import IO

from ros_isolated_test import __version__, names
from ros_isolated_test.report import html_assets
from ros_isolated_test.report.bounded_values import local
from ros_isolated_test.report.counts import FileReport
from ros_isolated_test.report.html_parts import Past, attr, text
from ros_isolated_test.report.html_timeline import Bar, write_timeline
from ros_isolated_test.report.spool import Spool
from ros_isolated_test.xunit.timeline import DOMAIN_POOL

#: Distinct values kept per fact (hosts, pools, ...); more are counted.
FACT_VALUES = 12
#: Values that could not be drawn, named on the page; more are counted.
ODD_VALUES = 20
#: The facts of the run, as the header's table names them, the property of each (the
#: host is the file's ``hostname``), and what a file of ours that lacks it means (None:
#: nothing that differs; the capacity is recorded only by tests that asked for resources).
FACTS: tuple[tuple[str, str | None, str | None], ...] = (
    ("host", None, "not recorded"),
    ("domain pool", DOMAIN_POOL, "no ID held"),
    ("capacity", "capacity", None),
    ("discovery range", "ros_discovery_range", "not recorded (isolation off)"),
    ("runner version", names.RUNNER_VERSION, "not recorded"),
)


class Page:
    """What the page needs once every file is read: counts, facts, bars, spools."""

    def __init__(self) -> None:
        #: Every file's counts, summed.
        self.total = FileReport(Path())
        self.bars: list[Bar] = []
        #: Per fact: files by value, files that did not record it, files past FACT_VALUES.
        self.facts: dict[str, dict[str, int]] = {name: {} for name, _, _ in FACTS}
        self.absent: dict[str, int] = {name: 0 for name, _, _ in FACTS}
        self.more: dict[str, int] = {name: 0 for name, _, _ in FACTS}
        #: "<file>: <value named>" for the first ODD_VALUES values not drawn; the count.
        self.odd: list[str] = []
        self.odd_count = 0
        self.files = 0
        self.foreign = 0
        self.attempts = 0
        # Spools: failures and errors, flaky cases, the rest (suite blocks, indexed).
        self.failures = Spool()
        self.flaky = Spool()
        self.rest = Spool()
        #: (package, suite, file number, offset, length, tests, listed above) per block.
        self.blocks: list[tuple[str, str, int, int, int, int, int]] = []
        #: A split's shares found (``I/N``, plan, hosts) and its problems (``shards``).
        self.shares: list[tuple[str, str, list[str]]] = []
        self.split_problems: list[str] = []
        #: The test history's word on each test (None: no history asked for), and where.
        self.history: dict[str, Past] | None = None
        self.history_source = ""

    def note(self, fact: str, value: str) -> None:
        """Count ``value`` of ``fact`` ("": not recorded); past FACT_VALUES only counted."""
        values = self.facts[fact]
        if not value:
            self.absent[fact] += 1
        elif value in values or len(values) < FACT_VALUES:
            values[value] = values.get(value, 0) + 1
        else:
            self.more[fact] += 1

    def name_odd(self, where: str, said: list[str]) -> None:
        """Keep what a file's reading named (values not drawn), up to ODD_VALUES in all."""
        for line in said:
            self.odd_count += 1
            if len(self.odd) < ODD_VALUES:
                self.odd.append(f"{where}: {line}")

    def close(self) -> None:
        for spool in (self.failures, self.flaky, self.rest):
            spool.close()


def assemble(page: Page, out: IO[bytes]) -> None:
    """The page in reading order: head, totals, facts, timeline, the three lists, script."""

    def put(text: str) -> None:
        out.write(text.encode("utf-8", "backslashreplace"))

    total = page.total
    verdict = "FAILED" if total.failed or page.split_problems else "PASSED"
    headline = _headline(total)
    if page.split_problems:
        headline += f"; the split's results are incomplete ({len(page.split_problems)} problem(s))"
    put(
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
        '<meta http-equiv="Content-Security-Policy" '
        f'content="{html_assets.CONTENT_SECURITY_POLICY}">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f'<meta name="generator" content="ros-isolated-test {escape(__version__)}">'
        f"<title>{verdict}: {escape(headline)} · ros-isolated-test report</title>"
        f"<style>{html_assets.STYLE}</style></head><body>"
        f'<header class="banner {verdict.lower()}"><h1>{verdict}</h1>'
        f"<p>{escape(headline)}</p></header><main>"
    )
    put(_split_problems_html(page))
    put(_totals_html(page))
    put(_facts_html(page))
    write_timeline(page.bars, put)
    put(
        '<div class=filterbar><input id=filter type=search placeholder="Filter tests by name" '
        'aria-label="Filter tests by name"></div>'
    )
    failures = total.errors + total.failures
    put(f"<section id=failures><h2>Failures and errors ({failures})</h2>")
    if page.failures.size:
        page.failures.copy_to(out)
    else:
        put("<p class=none>none</p>")
    flaky = f"Flaky: passed after failing ({total.flaky})"
    if total.skipped_after_failing:
        flaky += f", skipped after failing ({total.skipped_after_failing})"
    put(f"</section><section id=flaky><h2>{flaky}</h2>")
    if page.flaky.size:
        page.flaky.copy_to(out)
    else:
        put("<p class=none>none</p>")
    put("</section><section id=all><h2>Everything else, by package and suite</h2>")
    _grouped(page, out, put)
    put("</section></main><div id=card></div>")
    put(f"<script>{html_assets.SCRIPT}</script></body></html>\n")


def _headline(total: FileReport) -> str:
    said = [f"{total.tests} tests", f"{total.failures} failures", f"{total.errors} errors"]
    said.append(f"{total.skipped} skipped")
    if total.flaky:
        said.append(f"{total.flaky} flaky")
    return ", ".join(said)


def _split_problems_html(page: Page) -> str:
    """What is wrong with a split's merged trees, first: the totals below may be short."""
    if not page.split_problems:
        return ""
    items = "".join(f"<li>{text(line, 2048)}</li>" for line in page.split_problems)
    return (
        f"<section id=split-problems class=bad><h2>The split's results are incomplete "
        f"({len(page.split_problems)})</h2><ul>{items}</ul></section>"
    )


def _totals_html(page: Page) -> str:
    """The counts that add up to the tests, then the parts of them counted apart."""
    total = page.total
    items = [
        ("tests", total.tests, ""),
        ("passed", total.passed, ""),
        ("failures", total.failures, "bad" if total.failures else ""),
        ("errors", total.errors, "bad" if total.errors else ""),
        ("flaky", total.flaky, "warn" if total.flaky else ""),
        ("skipped", total.skipped, ""),
        ("result files", page.files, ""),
        ("attempts drawn", page.attempts, ""),
    ]
    if total.skipped_after_failing:
        items.insert(6, ("skipped after failing", total.skipped_after_failing, "warn"))
    if total.failed_then_not_run:
        items.insert(4, ("failed, then not run", total.failed_then_not_run, "bad"))
    cells = "".join(
        f'<div class="total {style}" id="total-{escape(name.replace(" ", "-").replace(",", ""))}">'
        f"<b>{value}</b>{escape(name)}</div>"
        for name, value, style in items
    )
    return f"<div class=totals>{cells}</div>"


def _facts_html(page: Page) -> str:
    rows = [
        f"<tr><th>{escape(fact)}</th>{_fact_cell(page, fact, absent)}</tr>"
        for fact, _, absent in FACTS
    ]
    if page.bars:
        first = min(bar.start for bar in page.bars)
        last = max(bar.end for bar in page.bars)
        rows.append(
            f"<tr><th>ran</th><td>{escape(local(first))} to {escape(local(last))} "
            f"({last - first:.1f} s)</td></tr>"
        )
    if page.shares:
        shares = "; ".join(
            f"{share} (plan {plan}{', on ' + ', '.join(hosts) if hosts else ''})"
            for share, plan, hosts in page.shares
        )
        rows.append(f"<tr><th>shards</th><td id=fact-shards>{text(shares, 8192)}</td></tr>")
    if page.history is not None:
        rows.append(
            f"<tr><th>history</th><td id=fact-history>{text(page.history_source, 1024)}: "
            f"{len(page.history)} test(s) in the runs before this one; each failure says "
            "whether it is new, known flaky or broken since a run, each test its strip of "
            "outcomes (oldest first, this run last)</td></tr>"
        )
    if page.foreign:
        rows.append(
            f"<tr><th>other producers</th><td>{page.foreign} result file(s) not written by "
            "ros-isolated-test (listed; on the timeline where they carry a timestamp)</td></tr>"
        )
    if page.odd_count:
        named = "".join(f"<li>{text(line, 512)}</li>" for line in page.odd)
        if page.odd_count > len(page.odd):
            named += f"<li>and {page.odd_count - len(page.odd)} more</li>"
        rows.append(
            f"<tr><th>not drawn</th><td id=odd-values>{page.odd_count} value(s) a result file "
            f"gave that the page cannot draw, drawn as unknown:<ul>{named}</ul></td></tr>"
        )
    rows.append(
        f"<tr><th>page</th><td>ros-isolated-test {escape(__version__)}, "
        f"{escape(local(datetime.datetime.now().timestamp()))}</td></tr>"
    )
    return f"<h2>Run</h2><table class=facts>{''.join(rows)}</table>"


def _fact_cell(page: Page, fact: str, absent: str | None) -> str:
    """A fact's values, each with its files when the files differ, and who did not say."""
    values, missing, more = page.facts[fact], page.absent[fact], page.more[fact]
    missing = missing if absent is not None else 0
    differs = len(values) + bool(missing) + bool(more) > 1
    said = [
        text(value, 256) + (f" ({count} file(s))" if differs else "")
        for value, count in sorted(values.items())
    ]
    if missing and absent is not None:
        said.append(
            f"<span class=none>{escape(absent)}</span>"
            + (f" ({missing} file(s))" if differs else "")
        )
    if more:
        said.append(f"and {more} more file(s) with other values")
    head = "<b class=differs>differs between files:</b> " if differs else ""
    cell = "; ".join(said) or "<span class=none>not recorded</span>"
    name = fact.replace(" ", "-")
    return f'<td id="fact-{name}" data-differs="{str(differs).lower()}">{head}{cell}</td>'


def _grouped(page: Page, out: IO[bytes], put: Callable[[str], None]) -> None:
    """Every suite block, by package and then suite, copied from the spool in that order."""
    if not page.blocks:
        put("<p class=none>no result files</p>")
        return
    by_package: dict[str, list[tuple[str, int, int, int, int, int]]] = {}
    for package, suite, number, offset, length, tests, listed in page.blocks:
        by_package.setdefault(package, []).append((suite, number, offset, length, tests, listed))
    for package in sorted(by_package):
        members = sorted(by_package[package])
        tests = sum(member[4] for member in members)
        put(
            f'<details class=pkg open data-package="{attr(package)}"><summary>'
            f"{text(package, 256)}<span class=counts>{len(members)} suite(s), "
            f"{tests} test(s)</span></summary>"
        )
        for _suite, _number, offset, length, _tests, _listed in members:
            page.rest.copy_to(out, offset, length)
        put("</details>")
