"""``report.html_page``: the page put together, the totals first although they are known last.

While files are read the page keeps only counts, a few distinct facts per kind, one
bar per attempt and three spools; then it streams the page in reading order. It is
self-contained: inline style and script, and a policy that forbids any request, so it
works as a CI artifact opened offline.
"""

from __future__ import annotations

import io
import re
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


def _fact(page: html.HtmlElement, fact: str) -> tuple[str, str]:
    [cell] = page.xpath(f"//td[@id='fact-{fact}']")
    return cell.get("data-differs"), " ".join(cell.text_content().split())


def test_the_run_table_says_when_files_differ_instead_of_showing_the_first_ones_values(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Some files ran with the default range (none recorded), on another pool, by another
    version: each fact names every value with its files, never only the first file's."""
    tree = tmp_path / "tree"
    paths = result_tree.write_tree(tree, 6, 1, pool=range(1, 4))
    for number, path in enumerate(paths[:2]):
        data = path.read_text(encoding="utf-8")
        data = re.sub(r'\s*<property name="ros_discovery_range" value="[^"]*"/>', "", data)
        data = data.replace('value="1-3"', 'value="50-52"')
        if number == 0:
            data = re.sub(r'(name="runner_version" value=")[^"]*', r"\g<1>0.0.9", data)
        path.write_text(data, encoding="utf-8")
    page = report_page(env, tmp_path / "page.html", tree)
    assert _fact(page, "discovery-range") == (
        "true",
        "differs between files: LOCALHOST (4 file(s)); not recorded (isolation off) (2 file(s))",
    )
    assert _fact(page, "domain-pool") == (
        "true",
        "differs between files: 1-3 (4 file(s)); 50-52 (2 file(s))",
    )
    differs, said = _fact(page, "runner-version")
    assert differs == "true" and "0.0.9 (1 file(s))" in said and "(5 file(s))" in said
    # The control: files that agree show their one value, with no counts.
    same = tmp_path / "same"
    result_tree.write_tree(same, 6, 1, pool=range(1, 4))
    page = report_page(env, tmp_path / "same.html", same)
    assert _fact(page, "discovery-range") == ("false", "LOCALHOST")
    assert _fact(page, "domain-pool") == ("false", "1-3")
