"""``report.html_timeline``: one bar per attempt, where and when it ran, on a time axis.

Bars come from what the runner records in each result file (an earlier attempt's from
its own ``attempt_<k>.`` properties) or from another producer's own timestamp when it
is plausible; rows are per domain ID (per host and ID when files come from several
machines), with lanes and a clash only where bars overlap in a row. Checked on the
functions, and on pages ``report --html`` writes, read as HTML.
"""

from __future__ import annotations

import datetime
import re
import shutil
from pathlib import Path

from helpers import result_tree
from helpers.chromium import with_class as cls
from helpers.commands import run_cli
from helpers.report_page import parsed, report_page, timeline_bars, timeline_rows
from helpers.results import load_result
from helpers.xunit import SAMPLES

from ros_isolated_test.report.bounded_values import Reading
from ros_isolated_test.report.counts import counted
from ros_isolated_test.report.html_timeline import Bar, bars_of, runs, timeline_html
from ros_isolated_test.xunit.model import Case, Outcome
from ros_isolated_test.xunit.raw import RawSuite, ReadResult
from ros_isolated_test.xunit.timeline import timeline_properties

START = 1_790_000_000.0
PASSED = counted(Path("t.xml"), [Case("pkg.C", "a")])
FAILED = counted(Path("t.xml"), [Case.saying("pkg.C", "a", Outcome.FAILURE, "m")])


def _recorded(attempt: int, start: float, domain: str) -> dict[str, str]:
    """What the runner records of one attempt, under ``attempt_<k>.`` unless the last."""
    prefix = "" if attempt == 0 else f"attempt_{attempt}."
    found = timeline_properties(start, start + 2.0, 1.5, 0.5, "1-3")
    found["ros_domain_id"] = domain
    return {f"{prefix}{name}": value for name, value in found.items()}


def test_each_attempt_kept_is_a_bar_and_an_earlier_failed_one_is_flaky() -> None:
    properties = {**_recorded(1, START, "1"), **_recorded(0, START + 10, "3"), "attempts": "3"}
    read = ReadResult(Path("t.xml"))
    bars = bars_of(properties, read, "pkg.t", "h", PASSED, "s1", Reading())
    # Attempt 2 was not kept (a long series keeps the first and last few): no bar.
    assert [(bar.attempt, bar.attempts, bar.domain, bar.state) for bar in bars] == [
        (1, 3, "1", "flaky"),
        (3, 3, "3", "passed"),
    ]
    assert [(bar.start, bar.end) for bar in bars] == [(START, START + 2), (START + 10, START + 12)]
    assert (bars[0].wait_domain, bars[0].wait_resources) == (1.0, 0.5)
    failing = bars_of(properties, read, "pkg.t", "h", FAILED, "f1-1", Reading())
    assert [bar.state for bar in failing] == ["failed", "failed"]  # no later pass: no flake
    off = bars_of(
        {**properties, "isolation": "disabled"}, read, "pkg.t", "h", PASSED, "s1", Reading()
    )
    assert [bar.domain for bar in off] == ["", ""]  # no ID of ours


def test_another_producers_file_is_drawn_from_its_own_plausible_timestamp() -> None:
    read = ReadResult(Path("t.xml"), root_tag="testsuites")
    read.suites = [
        RawSuite("placeholder", {"timestamp": "1970-01-01T00:00:00", "time": "5"}),
        RawSuite("real", {"timestamp": "2026-11-21T22:41:26Z", "time": "1,002.5"}),
    ]
    [bar] = bars_of({}, read, "gtest", "", FAILED, "f1-1", Reading())
    start = datetime.datetime(2026, 11, 21, 22, 41, 26, tzinfo=datetime.timezone.utc)
    assert (bar.start, bar.end - bar.start) == (start.timestamp(), 1002.5)
    assert (bar.state, bar.domain) == ("failed", "")
    read.suites = read.suites[:1]  # the control: a 1970 placeholder alone is no time at all
    assert bars_of({}, read, "gtest", "", FAILED, "f1-1", Reading()) == []


def test_an_axis_has_round_ticks_and_the_bars_their_lanes() -> None:
    one = Bar("pkg.a", "h", "5", START, START + 6.0, "passed", "s1")
    two = Bar("pkg.b", "h", "5", START + 4.0, START + 10.0, "failed", "f2-1")
    drawn = parsed(timeline_html([one, two]))
    labels = [tick.text_content() for tick in drawn.xpath(f"//div[{cls('tick')}]")]
    assert labels == ["0 s", "2 s", "4 s", "6 s", "8 s", ""]  # the right edge's is cut
    [row] = drawn.xpath(f"//div[{cls('trow')}]")
    assert "clash" in row.get("class").split()
    assert [bar.get("style").rsplit(";", 1)[1] for bar in drawn.xpath("//a")] == [
        "--lane:0",
        "--lane:1",
    ]
    apart = Bar("pkg.b", "h", "5", START + 6.0, START + 10.0, "failed", "f2-1")
    [row] = parsed(timeline_html([one, apart])).xpath(f"//div[{cls('trow')}]")
    assert "clash" not in row.get("class").split()  # one after the other: one lane


def test_where_each_attempt_ran_is_said_beside_the_file() -> None:
    first = Bar("pkg.t", "h", "1", START, START + 2.0, "flaky", "k1-1", 1, 2)
    last = Bar("pkg.t", "h", "3", START + 5, START + 6.5, "passed", "k1-1", 2, 2)
    said = parsed(f"<p>{runs([first, last])}</p>").text_content()
    assert said == "attempt 1 failed on ID 1, 2.00 sattempt 2 passed on ID 3, 1.50 s"
    assert timeline_html([]).endswith(
        "<p class=none>No result file says when it ran: nothing to draw.</p>"
    )


def test_each_kept_attempt_is_a_bar_the_earlier_ones_from_their_own_properties(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A merged file: attempt 1's ID and times come from ``attempt_1.*``, the rest as the last's."""
    tree = tmp_path / "tree"
    # Test 39 of a made-up tree is flaky: two attempts, the first failed on another ID.
    paths = result_tree.write_tree(tree, 40, 3, pool=range(1, 4))
    page = report_page(env, tmp_path / "page.html", tree)
    flaky = [b for b in timeline_bars(page) if b.get("data-test") == "pkg_019.test_00039"]
    assert [b.get("data-attempt") for b in flaky] == ["1", "2"]
    assert [b.get("data-state") for b in flaky] == ["flaky", "passed"]
    properties = load_result(paths[39]).properties
    assert flaky[0].get("data-domain") == properties["attempt_1.ros_domain_id"]
    assert flaky[1].get("data-domain") == properties["ros_domain_id"]
    assert flaky[0].get("data-domain") != flaky[1].get("data-domain")
    t0 = float(page.xpath("//*[@id='timeline']")[0].get("data-t0"))
    for bar, prefix in zip(flaky, ("attempt_1.", ""), strict=True):
        start = datetime.datetime.fromisoformat(properties[f"{prefix}started_at"]).timestamp()
        assert abs(t0 + float(bar.get("data-start")) - start) < 2e-6
    assert len(timeline_bars(page)) == 41  # one per attempt: 40 tests, one of them run twice
    assert min(float(b.get("data-start")) for b in timeline_bars(page)) == 0.0


def test_other_producers_are_listed_and_drawn_where_they_say_when_they_ran(
    env: dict[str, str], tmp_path: Path
) -> None:
    tree = tmp_path / "tree"
    tree.mkdir()
    samples = {
        "gtest": "gtest-1.17.0_env_failure.xml",  # a real timestamp, and a 1970 placeholder
        "pytest": "pytest-9.2_xunit2.xml",  # a timestamp with its zone
        "launch": "launch_testing_junitxml.xml",  # no timestamp at all
    }
    for sample in samples.values():
        shutil.copy(SAMPLES / sample, tree / sample)
    page = report_page(env, tmp_path / "page.html", tree)
    suites = {s.get("data-test") for s in page.xpath(f"//details[{cls('suite')}]")}
    assert suites == {"gtest-1.17.0_env_failure", "pytest-9.2_xunit2", "launch_testing_junitxml"}
    bars = {b.get("data-test"): b for b in timeline_bars(page)}
    assert set(bars) == {"gtest-1.17.0_env_failure", "pytest-9.2_xunit2"}
    assert all(b.get("data-domain") == "" for b in bars.values())
    assert {row.get("data-row") for row in timeline_rows(page)} == {"no domain ID"}
    # The gtest bar starts at its real timestamp (2026-11-21), not its suite's 1970 one.
    t0 = float(page.xpath("//*[@id='timeline']")[0].get("data-t0"))
    gtest_start = t0 + float(bars["gtest-1.17.0_env_failure"].get("data-start"))
    assert datetime.datetime.fromtimestamp(gtest_start).year == 2026
    # Every failure the text report counts is listed.
    text = run_cli(["report", str(tree)], env).stdout
    counted = re.search(r"Summary: \d+ tests, (\d+) errors, (\d+) failures", text)
    assert counted is not None
    listed = page.xpath(f"//section[@id='failures']//article[{cls('case')}]")
    assert len(listed) == int(counted.group(1)) + int(counted.group(2))


def test_hosts_merge_into_one_timeline_with_the_host_in_each_row(
    env: dict[str, str], tmp_path: Path
) -> None:
    """CI shards: each machine its own IDs (the same numbers); one page, rows per host."""
    for host in ("ci-1", "ci-2"):
        result_tree.write_tree(tmp_path / host, 12, 2, pool=range(5, 7), host=host)
    page = report_page(env, tmp_path / "page.html", tmp_path / "ci-1", tmp_path / "ci-2")
    rows = {row.get("data-row") for row in timeline_rows(page)}
    assert rows == {f"{host} · ID {domain}" for host in ("ci-1", "ci-2") for domain in (5, 6)}
    assert len(timeline_bars(page)) == 24
    assert not [row for row in timeline_rows(page) if "clash" in row.get("class").split()]
    # Control: one host alone names no host in its rows.
    alone = report_page(env, tmp_path / "alone.html", tmp_path / "ci-1")
    assert {row.get("data-row") for row in timeline_rows(alone)} == {"ID 5", "ID 6"}


def test_two_tests_at_once_on_one_id_of_one_host_are_shown_as_a_clash(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Two runs of one host that did not share a lock directory: the row says so."""
    for run in ("a", "b"):  # the same schedule twice: every bar overlaps its twin
        result_tree.write_tree(tmp_path / run, 4, 1, pool=range(9, 10), host="ci-1", seed=1)
    page = report_page(env, tmp_path / "page.html", tmp_path / "a", tmp_path / "b")
    (row,) = timeline_rows(page)
    assert "clash" in row.get("class").split()
    assert row.xpath(f"./div[{cls('tlane')}]")[0].get("style") == "--lanes:2"
    # Control: one of them alone has one lane and no clash.
    alone = report_page(env, tmp_path / "alone.html", tmp_path / "a")
    (row,) = timeline_rows(alone)
    assert "clash" not in row.get("class").split()


def test_a_timed_out_test_has_its_own_colour(one_id: dict[str, str], tmp_path: Path) -> None:
    results = tmp_path / "results"
    slow = run_cli(
        ["run", "--junit-xml", str(results / "slow.xml"), "--timeout", "0.5", "--", "sleep", "60"],
        one_id,
    )
    assert slow.returncode == 124, slow.stderr
    quick = run_cli(["run", "--junit-xml", str(results / "quick.xml"), "--", "true"], one_id)
    assert quick.returncode == 0, quick.stderr
    page = report_page(one_id, tmp_path / "page.html", results)
    states = {b.get("data-test"): b.get("data-state") for b in timeline_bars(page)}
    assert states == {"results.slow": "timeout", "results.quick": "passed"}
