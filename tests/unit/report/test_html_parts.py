"""``report.html_parts``: the page's small pieces, text as the page shows it and each case's block.

Every part clips and escapes its text the same way, so a name or message is always
text and never markup; the blocks of failed, flaky and other cases go to spools
(temporary files) as each result file is read, so the page needs bounded memory.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path

from helpers import capabilities, chromium
from helpers.chromium import with_class as cls
from helpers.commands import run_cli
from helpers.report_page import parsed, report_page, timeline_bars
from lxml import html

from ros_isolated_test.report.counts import counted
from ros_isolated_test.report.html_parts import attr, text, write_case, write_suite
from ros_isolated_test.report.spool import Spool
from ros_isolated_test.xunit import serialise
from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE
from ros_isolated_test.xunit.model import Attempt, Case, Outcome, Suite
from ros_isolated_test.xunit.timeline import timeline_properties


def _written(write: Callable[[Spool], None]) -> html.HtmlElement:
    """What a writer put in a fresh spool, parsed as HTML."""
    spool = Spool()
    try:
        write(spool)
        out = io.BytesIO()
        spool.copy_to(out)
    finally:
        spool.close()
    return parsed(f"<div>{out.getvalue().decode()}</div>")


def test_text_is_cut_to_its_head_or_tail_and_escaped() -> None:
    assert text("a<b>&c", 100) == "a&lt;b&gt;&amp;c"
    assert text("x" * 10 + "y" * 10, 10) == "x" * 10 + "\n[... 10 more characters ...]"
    assert text("x" * 10 + "y" * 10, 10, tail=True) == "[... 10 characters before ...]\n" + (
        "y" * 10
    )
    # A byte that was not UTF-8 (a file name's) is shown, never a lone surrogate.
    assert text("caf\udce9 \ud800", 100) == "caf\\xe9 \\ud800"
    assert text("short", 5) == "short"  # the control: at the limit, nothing is cut
    assert attr('say "<hi>"') == "say &quot;&lt;hi&gt;&quot;"


def test_a_failed_case_shows_its_message_its_text_and_the_tail_of_its_output() -> None:
    case = Case.saying("pkg.C", "a", Outcome.FAILURE, "assert 1 == 2")
    case.text = "Traceback: assert 1 == 2"
    case.system_out = "o" * 5000 + "THE END"
    block = _written(lambda spool: write_case(spool, case, "f1-1", "pkg.t", "t.xml", ""))
    [article] = block.xpath("//article")
    assert (article.get("id"), article.get("data-outcome")) == ("f1-1", "failure")
    assert article.xpath(f".//span[{cls('tag')}]")[0].text == "failure"
    assert article.xpath("//pre[@class='message']")[0].text == "assert 1 == 2"
    assert "Traceback: assert 1 == 2" in [pre.text for pre in article.xpath(".//pre")]
    tail = article.xpath(".//details/pre")[0].text
    assert tail.startswith("[... 911 characters before ...]") and tail.endswith("THE END")


def test_a_case_failed_then_not_run_and_a_flaky_one_are_named_so() -> None:
    not_run = Case.saying("pkg.C", "a", Outcome.FAILURE, "Failed, then not run", NOT_RUN_AGAIN_TYPE)
    block = _written(lambda spool: write_case(spool, not_run, "f1-1", "pkg.t", "t.xml", ""))
    assert block.xpath(f"//span[{cls('tag')}]")[0].text == "failed, then not run"
    flaky = Case("pkg.C", "b", attempts=[Attempt("flakyError", "first try")])
    block = _written(lambda spool: write_case(spool, flaky, "k1-1", "pkg.t", "t.xml", ""))
    [article] = block.xpath("//article")
    assert (article.get("class"), article.get("data-outcome")) == ("case flaky", "flaky")
    assert "1 failed attempt(s), then passed:" in article.text_content()
    assert [item.text_content() for item in article.xpath(".//li")] == ["errorfirst try"]


def test_a_suites_block_lists_only_the_cases_not_listed_above() -> None:
    cases = [
        Case("pkg.C", "ok", time=0.5),
        Case.saying("pkg.C", "later", Outcome.SKIPPED, "no GPU\nsecond line"),
        Case.saying("pkg.C", "bad", Outcome.FAILURE, "m"),
    ]
    report = counted(Path("t.xml"), cases)
    block = _written(lambda spool: write_suite(spool, "s1", "pkg.t", "t.xml", report, cases))
    [suite] = block.xpath("//details")
    assert "3 test(s), 1 passed, 1 skipped, 1 failed" in suite.xpath("./summary")[0].text_content()
    rows = [row.text_content() for row in suite.xpath(".//tr[contains(@class, 'c ')]")]
    assert rows == ["ok0.500 spassed", "later0.000 sskipped: no GPU"]
    listed = cases[2:]
    block = _written(
        lambda spool: write_suite(spool, "s2", "pkg.t", "t.xml", counted(Path("t"), listed), listed)
    )
    assert block.xpath("//p[@class='none']")[0].text == "every case is listed above"


def test_names_and_messages_are_text_never_markup(env: dict[str, str], tmp_path: Path) -> None:
    hostile = "<script>document.title='owned'</script><img src=x onerror=alert(1)>"
    tree = tmp_path / "tree"
    tree.mkdir()
    (tree / "evil.xml").write_text(
        '<testsuite name="s" tests="1" failures="1"><testcase classname="c" name="'
        + hostile.replace("<", "&lt;").replace(">", "&gt;").replace("'", "&apos;")
        + '"><failure message="m">'
        + hostile.replace("<", "&lt;").replace(">", "&gt;")
        + "</failure></testcase></testsuite>"
    )
    page = report_page(env, tmp_path / "page.html", tree)
    assert len(page.xpath("//script")) == 1  # the page's own
    assert page.xpath("//img") == []
    (case,) = page.xpath(f"//article[{cls('case')}]")
    assert hostile in case.text_content()  # shown, as text


# --- direction controls: a name cannot read as another (issue 35, item 4) ----------------------

#: Reads "passing ok" when drawn raw: the override reverses "gnissap".
SPOOFED = "\u202egnissap\u202c ok"
#: Every direction control: embeddings, overrides, isolates and the marks.
DIRECTION_CONTROLS = "\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069\u200e\u200f\u061c"


def test_direction_controls_are_shown_as_their_code_in_text_and_attributes() -> None:
    assert text(SPOOFED, 100) == "\\u202egnissap\\u202c ok"
    assert attr(SPOOFED) == "\\u202egnissap\\u202c ok"
    shown = text(DIRECTION_CONTROLS, 1000)
    assert not set(shown) & set(DIRECTION_CONTROLS)
    assert shown.count("\\u") == len(DIRECTION_CONTROLS)
    # The control: right-to-left text itself (Hebrew, Arabic) is shown as it is.
    assert text("שלום مرحبا", 100) == "שלום مرحبا"


@capabilities.CHROMIUM.mark
def test_a_name_that_reverses_itself_is_drawn_with_its_controls_shown_in_chromium(
    env: dict[str, str], tmp_path: Path
) -> None:
    """In headings and on the timeline, after the page's scripts ran; "passing ok" is not."""
    tree = tmp_path / "tree"
    tree.mkdir()
    started = timeline_properties(1_790_000_000.0, 1_790_000_002.0, 0.0, 0.0, "1-8")
    for name in (SPOOFED, "plain ok"):  # the second: the control, a name as it is
        case = Case.saying(f"pkg.{name}.C", name, Outcome.FAILURE, f"{name} failed")
        properties = {**started, "runner_version": "0.1.0", "ros_domain_id": "3"}
        suite = Suite(f"pkg.{name}", [case], 2.0, "2026-09-21T14:13:20", "h", properties)
        (tree / f"{name[-8:].strip()}.xml").write_bytes(serialise.serialize(suite))
    page = tmp_path / "page.html"
    proc = run_cli(["report", "--html", str(page), str(tree)], env)
    assert proc.returncode == 1, proc.stderr
    dom = chromium.dump_dom(page)
    body = dom.xpath("//body")[0].text_content()
    assert not set(body) & set(DIRECTION_CONTROLS)
    headings = [node.text_content() for node in dom.xpath("//article//h3")]
    assert any("\\u202egnissap\\u202c ok" in heading for heading in headings), headings
    assert any("plain ok" in heading for heading in headings), headings  # the control
    labels = [bar.text_content() for bar in timeline_bars(dom)]
    assert sorted(labels) == ["\\u202egnissap\\u202c ok", "plain ok"]
    for bar in timeline_bars(dom):
        for value in bar.attrib.values():
            assert not set(value) & set(DIRECTION_CONTROLS), value
