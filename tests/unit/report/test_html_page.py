"""``report.html_page``: the page put together, the totals first although they are known last.

While files are read the page keeps only counts, a few distinct facts per kind, one
bar per attempt and three spools; then it streams the page in reading order. It is
self-contained: inline style and script, and a policy that forbids any request, so it
works as a CI artifact opened offline.
"""

from __future__ import annotations

import io
from pathlib import Path

from helpers import chromium, result_tree
from helpers.report_page import parsed, report_page
from lxml import html

from ros_isolated_test.report import html_assets
from ros_isolated_test.report.counts import counted
from ros_isolated_test.report.html_page import FACT_VALUES, Page, assemble
from ros_isolated_test.xunit.model import Case, Outcome


def _assembled(page: Page) -> html.HtmlElement:
    out = io.BytesIO()
    try:
        assemble(page, out)
    finally:
        page.close()
    return parsed(out.getvalue().decode())


def test_a_fact_keeps_a_few_distinct_values_and_counts_the_rest() -> None:
    page = Page()
    try:
        for number in range(FACT_VALUES + 8):
            page.note("host", f"host-{number}")
        page.note("host", "host-0")
        assert len(page.facts["host"]) == FACT_VALUES
        assert (page.facts["host"]["host-0"], page.more["host"]) == (2, 8)
    finally:
        page.close()


def test_the_page_opens_with_the_verdict_and_the_totals_then_the_lists_in_order() -> None:
    page = Page()
    page.total.include(counted(Path("a.xml"), [Case.saying("pkg.C", "a", Outcome.ERROR, "m")]))
    page.total.include(counted(Path("b.xml"), [Case("pkg.C", "b"), Case("pkg.C", "c")]))
    page.failures.write("<article id=f1-1>the failure</article>")
    drawn = _assembled(page)
    assert drawn.xpath("//header/h1")[0].text == "FAILED"
    assert drawn.findtext(".//title").startswith("FAILED: 3 tests, 0 failures, 1 errors, 0 skipped")
    assert drawn.xpath("//*[@id='total-errors']/b")[0].text == "1"
    assert drawn.xpath("//*[@id='total-passed']/b")[0].text == "2"
    ids = [node.get("id") for node in drawn.iter() if node.get("id")]
    # The totals come first although they are known last, the spooled failure in its list.
    order = ["total-tests", "fact-host", "failures", "f1-1", "flaky", "all"]
    assert [name for name in ids if name in order] == order
    assert drawn.xpath("//section[@id='flaky']/p")[0].text == "none"
    passing = Page()
    passing.total.include(counted(Path("b.xml"), [Case("pkg.C", "b")]))
    assert _assembled(passing).xpath("//header/h1")[0].text == "PASSED"  # the control


def test_the_page_names_nothing_to_fetch_and_forbids_fetching(
    env: dict[str, str], tmp_path: Path
) -> None:
    result_tree.write_tree(tmp_path / "tree", 60, 3)
    out = tmp_path / "page.html"
    page = report_page(env, out, tmp_path / "tree")
    assert chromium.external_references(out.read_text(encoding="utf-8")) == []
    (policy,) = page.xpath("//meta[@http-equiv='Content-Security-Policy']")
    assert policy.get("content") == html_assets.CONTENT_SECURITY_POLICY
    assert "default-src 'none'" in policy.get("content")
    # Control: the checker sees every way a page could fetch something.
    fetching = (
        '<html><head><link rel=stylesheet href="https://fonts.example/a.css">'
        "<style>@import 'b.css'; body{background:url(//cdn.example/c.png)}</style></head>"
        '<body><img src="d.png"><a href="#here">here</a></body></html>'
    )
    assert chromium.external_references(fetching) == [
        "https://fonts.example/a.css",
        "b.css",
        "//cdn.example/c.png",
        "d.png",
    ]
