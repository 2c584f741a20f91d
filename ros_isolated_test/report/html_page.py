"""The report page put together: what it keeps while files are read, then its parts in order.

:class:`Page` is all that is kept while result files are read: counts, a few distinct
facts per kind, one bar per attempt and three spools of case blocks. Once every file is
read, :func:`assemble` streams the page in reading order (the totals first although they
are known last), copying the spools into it. Apart from the reading of each file
(``html_report``) so that the page's layout reads in one place.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable
from html import escape
from typing import IO

from ros_isolated_test import __version__
from ros_isolated_test.report import html_assets
from ros_isolated_test.report.counts import FileReport
from ros_isolated_test.report.html_parts import Spool, attr, local, text
from ros_isolated_test.report.html_timeline import Bar, timeline_html
from ros_isolated_test.xunit.timeline import DOMAIN_POOL

#: Distinct values kept per fact (hosts, pools, ...); more are counted.
FACT_VALUES = 12
#: The facts of the run, as the header's table names them, and the property of each.
FACTS = (
    ("host", None),
    ("domain pool", DOMAIN_POOL),
    ("capacity", "capacity"),
    ("discovery range", "ros_discovery_range"),
    ("runner version", "runner_version"),
)


class Page:
    """What the page needs once every file is read: counts, facts, bars, spools."""

    def __init__(self) -> None:
        self.reports: list[FileReport] = []
        self.bars: list[Bar] = []
        self.facts: dict[str, dict[str, int]] = {name: {} for name, _ in FACTS}
        self.files = 0
        self.foreign = 0
        self.attempts = 0
        # Spools: failures and errors, flaky cases, the rest (suite blocks, indexed).
        self.failures = Spool()
        self.flaky = Spool()
        self.rest = Spool()
        #: (package, suite, file number, offset, length, tests, listed above) per block.
        self.blocks: list[tuple[str, str, int, int, int, int, int]] = []

    def note(self, fact: str, value: str) -> None:
        """Count ``value`` of ``fact``; beyond FACT_VALUES distinct ones only counted."""
        values = self.facts[fact]
        if value in values or len(values) < FACT_VALUES:
            values[value] = values.get(value, 0) + 1
        else:
            values[""] = values.get("", 0) + 1

    def close(self) -> None:
        for spool in (self.failures, self.flaky, self.rest):
            spool.close()


def assemble(page: Page, out: IO[bytes]) -> None:
    """The page in reading order: head, totals, facts, timeline, the three lists, script."""

    def put(text: str) -> None:
        out.write(text.encode("utf-8", "backslashreplace"))

    totals = _totals(page.reports)
    failed = totals["errors"] + totals["failures"]
    verdict = "FAILED" if failed else "PASSED"
    headline = _headline(totals)
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
    put(_totals_html(totals, page))
    put(_facts_html(page))
    put(timeline_html(page.bars))
    put(
        '<div class=filterbar><input id=filter type=search placeholder="Filter tests by name" '
        'aria-label="Filter tests by name"></div>'
    )
    failures = totals["errors"] + totals["failures"]
    put(f"<section id=failures><h2>Failures and errors ({failures})</h2>")
    if page.failures.size:
        page.failures.copy_to(out)
    else:
        put("<p class=none>none</p>")
    put(f"</section><section id=flaky><h2>Flaky: passed after failing ({totals['flaky']})</h2>")
    if page.flaky.size:
        page.flaky.copy_to(out)
    else:
        put("<p class=none>none</p>")
    put("</section><section id=all><h2>Everything else, by package and suite</h2>")
    _grouped(page, out, put)
    put("</section></main><div id=card></div>")
    put(f"<script>{html_assets.SCRIPT}</script></body></html>\n")


def _totals(reports: list[FileReport]) -> dict[str, int]:
    keys = ("tests", "errors", "failures", "skipped", "flaky")
    found = {key: sum(getattr(item, key) for item in reports) for key in keys}
    found["failed_then_not_run"] = sum(len(item.not_run_again) for item in reports)
    return found


def _headline(totals: dict[str, int]) -> str:
    said = [
        f"{totals['tests']} tests",
        f"{totals['failures']} failures",
        f"{totals['errors']} errors",
    ]
    said.append(f"{totals['skipped']} skipped")
    if totals["flaky"]:
        said.append(f"{totals['flaky']} flaky")
    return ", ".join(said)


def _totals_html(totals: dict[str, int], page: Page) -> str:
    passed = totals["tests"] - totals["errors"] - totals["failures"] - totals["skipped"]
    items = [
        ("tests", totals["tests"], ""),
        ("passed", passed - totals["flaky"], ""),
        ("failures", totals["failures"], "bad" if totals["failures"] else ""),
        ("errors", totals["errors"], "bad" if totals["errors"] else ""),
        ("flaky", totals["flaky"], "warn" if totals["flaky"] else ""),
        ("skipped", totals["skipped"], ""),
        ("result files", page.files, ""),
        ("attempts drawn", page.attempts, ""),
    ]
    if totals["failed_then_not_run"]:
        items.insert(4, ("failed, then not run", totals["failed_then_not_run"], "bad"))
    cells = "".join(
        f'<div class="total {style}" id="total-{escape(name.replace(" ", "-").replace(",", ""))}">'
        f"<b>{value}</b>{escape(name)}</div>"
        for name, value, style in items
    )
    return f"<div class=totals>{cells}</div>"


def _facts_html(page: Page) -> str:
    rows = []
    for fact, _ in FACTS:
        values = page.facts[fact]
        shown_values = [
            f"{text(value, 256)}" + (f" ({count} files)" if len(values) > 1 else "")
            for value, count in sorted(values.items())
            if value
        ]
        if "" in values:
            shown_values.append(f"and {values['']} more file(s) with other values")
        rows.append(
            f'<tr><th>{escape(fact)}</th><td id="fact-{fact.replace(" ", "-")}">'
            f"{'; '.join(shown_values) or '<span class=none>not recorded</span>'}</td></tr>"
        )
    if page.bars:
        first = min(bar.start for bar in page.bars)
        last = max(bar.end for bar in page.bars)
        rows.append(
            f"<tr><th>ran</th><td>{escape(local(first))} to {escape(local(last))} "
            f"({last - first:.1f} s)</td></tr>"
        )
    if page.foreign:
        rows.append(
            f"<tr><th>other producers</th><td>{page.foreign} result file(s) not written by "
            "ros-isolated-test (listed; on the timeline where they carry a timestamp)</td></tr>"
        )
    rows.append(
        f"<tr><th>page</th><td>ros-isolated-test {escape(__version__)}, "
        f"{escape(local(datetime.datetime.now().timestamp()))}</td></tr>"
    )
    return f"<h2>Run</h2><table class=facts>{''.join(rows)}</table>"


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
