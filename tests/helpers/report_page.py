"""The ``report --html`` page as the unit tests read it: written by the real CLI, parsed as HTML.

No browser: lxml reads the page, and XPath finds the timeline's bars and rows by their
classes (``tests/e2e`` opens the same page in Chromium).
"""

from __future__ import annotations

import re
from pathlib import Path

from lxml import html

from helpers.chromium import with_class
from helpers.commands import run_cli

#: Local ISO 8601 to the microsecond, with the zone: how the runner records an instant.
ISO_MICRO = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}[+-]\d\d:\d\d$")


def parsed(markup: str | bytes) -> html.HtmlElement:
    """``markup`` (a page, or a part of one) as lxml's HTML parser reads it."""
    return html.fromstring(markup)


def report_page(env: dict[str, str], out: Path, *paths: Path) -> html.HtmlElement:
    """``report --html out paths...`` run for real, and the page it wrote, parsed."""
    proc = run_cli(["report", "--html", str(out), *map(str, paths)], env)
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    return parsed(out.read_text(encoding="utf-8"))


def timeline_bars(page: html.HtmlElement) -> list[html.HtmlElement]:
    """Every attempt's bar on the page's timeline."""
    return list(page.xpath(f"//*[@id='timeline']//a[{with_class('bar')}]"))


def timeline_rows(page: html.HtmlElement) -> list[html.HtmlElement]:
    """Every row (one per host and domain ID) of the page's timeline."""
    return list(page.xpath(f"//*[@id='timeline']//div[{with_class('trow')}]"))


def page_totals(page: html.HtmlElement) -> dict[str, int]:
    """The page's counts of cases (not of files or bars), by their names, as drawn."""
    found = {}
    for cell in page.xpath(f"//div[{with_class('totals')}]/div[{with_class('total')}]"):
        name = "".join(cell.xpath("./text()")).strip().replace(",", "")
        if name not in ("result files", "attempts drawn"):
            found[name] = int(cell.findtext("b"))
    return {name: value for name, value in found.items() if value}
