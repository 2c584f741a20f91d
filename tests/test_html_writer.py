"""The report page's writer, and what the runner records for its timeline.

The page is read here as HTML (lxml), without a browser: which bars a result file
gives, from ours and from other producers' files, rows and lanes, escaping, nothing
fetched, the ``--html`` option's errors, bounded memory. What the runner records is
checked on real runs: when each attempt ran, to the microsecond, and what its wait was
for (an ID, or the resources). tests/test_html_report.py opens the page in Chromium.
"""

from __future__ import annotations

import datetime
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from helpers import chromium, gate, result_tree
from helpers.chromium import with_class as cls
from helpers.commands import CLI, run_cli, start_cli
from helpers.domains import free_ids
from helpers.peak_rss import measure
from helpers.processes import poll_until
from helpers.results import load_result
from lxml import html

from ros_isolated_test.xunit import html_assets
from ros_isolated_test.xunit.result_file import instant

SAMPLES = Path(__file__).resolve().parent / "data" / "xunit"
GATE = Path(gate.__file__)
ISO_MICRO = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}[+-]\d\d:\d\d$")


def _page(env: dict[str, str], out: Path, *paths: Path) -> html.HtmlElement:
    proc = run_cli(["report", "--html", str(out), *map(str, paths)], env)
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    return html.fromstring(out.read_text(encoding="utf-8"))


def _bars(page: html.HtmlElement) -> list[html.HtmlElement]:
    return list(page.xpath(f"//*[@id='timeline']//a[{cls('bar')}]"))


def _rows(page: html.HtmlElement) -> list[html.HtmlElement]:
    return list(page.xpath(f"//*[@id='timeline']//div[{cls('trow')}]"))


# -- what the runner records --------------------------------------------------------------


def test_instants_keep_the_microsecond_and_the_zone() -> None:
    now = time.time()
    text = instant(now)
    assert ISO_MICRO.match(text), text
    assert abs(datetime.datetime.fromisoformat(text).timestamp() - now) < 2e-6
    # Control: the suite's own timestamp keeps neither.
    assert not ISO_MICRO.match(instant(now)[:19])


def _gated(
    env: dict[str, str],
    root: Path,
    name: str,
    started: list[subprocess.Popen[bytes]],
    *options: str,
) -> None:
    """``run`` of a gate test (helpers/gate.py) named ``name``, in the background."""
    command = [sys.executable, str(GATE), str(root), name, "pass"]
    result = root / f"{name}.xml"
    log = root / f"{name}.log"
    start_cli(["run", "--junit-xml", str(result), *options, "--", *command], env, log, started)


def _queued(env: dict[str, str]) -> set[str]:
    """The gate tests whose runners wait in the queue, as ``status --json`` shows them."""
    rows = json.loads(run_cli(["status", "--json"], env).stdout)
    return {str(row["command"]).split()[-2] for row in rows if row["via"] == "queue"}


def test_each_wait_is_recorded_as_for_an_id_or_for_resources(
    env: dict[str, str], tmp_path: Path, started: list[subprocess.Popen[bytes]]
) -> None:
    """One runner waits for the only ID of its pool, one for the only CPU while IDs are free."""
    one, two, three = free_ids(3)
    capacity = {**env, "ROS_ISOLATED_TEST_CAPACITY": "cpu=1"}
    id_env = {**capacity, "ROS_ISOLATED_TEST_DOMAINS": str(one)}
    cpu_env = {**capacity, "ROS_ISOLATED_TEST_DOMAINS": f"{two},{three}"}
    _gated(id_env, tmp_path, "holds_id", started)
    _gated(cpu_env, tmp_path, "holds_cpu", started, "--resources", "cpu=1")
    poll_until(lambda: len(list(tmp_path.glob("holds_*.ready.1"))) == 2, "both holders run")
    _gated(id_env, tmp_path, "waits_id", started)
    _gated(cpu_env, tmp_path, "waits_cpu", started, "--resources", "cpu=1")
    poll_until(lambda: _queued(id_env) == {"waits_id", "waits_cpu"}, "both waiters queued")
    # One at a time, so neither waiter is ever behind the other: each waits for one thing.
    for holder, waiter in (("holds_id", "waits_id"), ("holds_cpu", "waits_cpu")):
        (tmp_path / f"{holder}.go.1").touch()
        poll_until((tmp_path / f"{waiter}.ready.1").exists, f"{waiter} runs")
        (tmp_path / f"{waiter}.go.1").touch()
    assert [process.wait() for process in started] == [0, 0, 0, 0]
    found = {
        name: load_result(tmp_path / f"{name}.xml").properties
        for name in ("holds_id", "holds_cpu", "waits_id", "waits_cpu")
    }
    assert float(found["waits_id"]["wait_domain_seconds"]) > 0
    assert found["waits_id"]["wait_resources_seconds"] == "0.000"
    assert float(found["waits_cpu"]["wait_resources_seconds"]) > 0
    assert found["waits_cpu"]["wait_domain_seconds"] == "0.000"
    assert found["waits_cpu"]["resources"] == "cpu=1"
    # Control: who found what they asked for free waited for nothing.
    for name in ("holds_id", "holds_cpu"):
        assert found[name]["wait_domain_seconds"] == "0.000"
        assert found[name]["wait_resources_seconds"] == "0.000"
    # Each waiter started after its holder ended: the times say so, to the microsecond.
    for holder, waiter in (("holds_id", "waits_id"), ("holds_cpu", "waits_cpu")):
        for name in (holder, waiter):
            assert ISO_MICRO.match(found[name]["started_at"])
            assert ISO_MICRO.match(found[name]["ended_at"])
        ended = datetime.datetime.fromisoformat(found[holder]["ended_at"])
        assert ended <= datetime.datetime.fromisoformat(found[waiter]["started_at"])
    assert found["waits_id"]["domain_pool"] == str(one)


# -- the page, as HTML ---------------------------------------------------------------------


def test_each_kept_attempt_is_a_bar_the_earlier_ones_from_their_own_properties(
    env: dict[str, str], tmp_path: Path
) -> None:
    """A merged file: attempt 1's ID and times come from ``attempt_1.*``, the rest as the last's."""
    tree = tmp_path / "tree"
    # Test 39 of a made-up tree is flaky: two attempts, the first failed on another ID.
    paths = result_tree.write_tree(tree, 40, 3, pool=range(1, 4))
    page = _page(env, tmp_path / "page.html", tree)
    flaky = [b for b in _bars(page) if b.get("data-test") == "pkg_019.test_00039"]
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
    assert len(_bars(page)) == 41  # one per attempt: 40 tests, one of them run twice
    assert min(float(b.get("data-start")) for b in _bars(page)) == 0.0


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
    page = _page(env, tmp_path / "page.html", tree)
    suites = {s.get("data-test") for s in page.xpath(f"//details[{cls('suite')}]")}
    assert suites == {"gtest-1.17.0_env_failure", "pytest-9.2_xunit2", "launch_testing_junitxml"}
    bars = {b.get("data-test"): b for b in _bars(page)}
    assert set(bars) == {"gtest-1.17.0_env_failure", "pytest-9.2_xunit2"}
    assert all(b.get("data-domain") == "" for b in bars.values())
    assert {row.get("data-row") for row in _rows(page)} == {"no domain ID"}
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
    page = _page(env, tmp_path / "page.html", tmp_path / "ci-1", tmp_path / "ci-2")
    rows = {row.get("data-row") for row in _rows(page)}
    assert rows == {f"{host} · ID {domain}" for host in ("ci-1", "ci-2") for domain in (5, 6)}
    assert len(_bars(page)) == 24
    assert not [row for row in _rows(page) if "clash" in row.get("class").split()]
    # Control: one host alone names no host in its rows.
    alone = _page(env, tmp_path / "alone.html", tmp_path / "ci-1")
    assert {row.get("data-row") for row in _rows(alone)} == {"ID 5", "ID 6"}


def test_two_tests_at_once_on_one_id_of_one_host_are_shown_as_a_clash(
    env: dict[str, str], tmp_path: Path
) -> None:
    """Two runs of one host that did not share a lock directory: the row says so."""
    for run in ("a", "b"):  # the same schedule twice: every bar overlaps its twin
        result_tree.write_tree(tmp_path / run, 4, 1, pool=range(9, 10), host="ci-1", seed=1)
    page = _page(env, tmp_path / "page.html", tmp_path / "a", tmp_path / "b")
    (row,) = _rows(page)
    assert "clash" in row.get("class").split()
    assert row.xpath(f"./div[{cls('tlane')}]")[0].get("style") == "--lanes:2"
    # Control: one of them alone has one lane and no clash.
    alone = _page(env, tmp_path / "alone.html", tmp_path / "a")
    (row,) = _rows(alone)
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
    page = _page(one_id, tmp_path / "page.html", results)
    states = {b.get("data-test"): b.get("data-state") for b in _bars(page)}
    assert states == {"results.slow": "timeout", "results.quick": "passed"}


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
    page = _page(env, tmp_path / "page.html", tree)
    assert len(page.xpath("//script")) == 1  # the page's own
    assert page.xpath("//img") == []
    (case,) = page.xpath(f"//article[{cls('case')}]")
    assert hostile in case.text_content()  # shown, as text


def test_the_page_names_nothing_to_fetch_and_forbids_fetching(
    env: dict[str, str], tmp_path: Path
) -> None:
    result_tree.write_tree(tmp_path / "tree", 60, 3)
    out = tmp_path / "page.html"
    page = _page(env, out, tmp_path / "tree")
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


# -- the option ----------------------------------------------------------------------------


def test_the_text_report_and_its_exit_code_stay_with_html(
    env: dict[str, str], tmp_path: Path
) -> None:
    failing, passing = tmp_path / "failing", tmp_path / "passing"
    for sample in ("gtest-1.17.0_mixed.gtest.xml", "xmlrunner-4.0_per_class_file.xml"):
        (failing if "gtest" in sample else passing).mkdir()
        shutil.copy(SAMPLES / sample, (failing if "gtest" in sample else passing) / sample)
    for tree, code in ((failing, 1), (passing, 0)):
        plain = run_cli(["report", "-v", str(tree)], env)
        page = tmp_path / f"{tree.name}.html"
        with_page = run_cli(["report", "-v", "--html", str(page), str(tree)], env)
        assert (plain.returncode, with_page.returncode) == (code, code)
        assert with_page.stdout == plain.stdout
        assert page.is_file()


def test_a_page_that_cannot_be_written_is_one_line_and_exit_2(
    env: dict[str, str], tmp_path: Path
) -> None:
    tree = tmp_path / "tree"
    result_tree.write_tree(tree, 3, 1)
    folder = tmp_path / "a_folder"
    folder.mkdir()
    fifo = tmp_path / "a_fifo"
    os.mkfifo(fifo)
    for target, said in ((folder, "it is a directory"), (fifo, "it is a FIFO")):
        proc = run_cli(["report", "--html", str(target), str(tree)], env)
        assert proc.returncode == 2, proc.stderr
        (line,) = proc.stderr.splitlines()
        assert line.startswith(f"ros-isolated-test: error: cannot write --html {target}: {said}")
    assert fifo.exists() and not fifo.is_file()  # never replaced
    # The null device discards the page; the report is as without it.
    proc = run_cli(["report", "--html", os.devnull, str(tree)], env)
    assert proc.returncode == 0, proc.stderr
    # Control: a regular path is written.
    proc = run_cli(["report", "--html", str(tmp_path / "ok.html"), str(tree)], env)
    assert proc.returncode == 0 and (tmp_path / "ok.html").is_file()


def test_memory_stays_bounded_as_the_tree_grows(env: dict[str, str], tmp_path: Path) -> None:
    """Ten times the files and cases: the page grows ten times, the writer's memory does not."""
    peaks = {}
    for files in (150, 1500):
        tree = tmp_path / f"tree{files}"
        result_tree.write_tree(tree, files, 20)
        page = tmp_path / f"page{files}.html"
        peak = measure([CLI, "report", "--html", str(page), str(tree)], env=env)
        assert peak.returncode == 1 and not peak.timed_out
        peaks[files] = (peak.max_rss, page.stat().st_size)
    (small_rss, small_page), (big_rss, big_page) = peaks[150], peaks[1500]
    assert big_page > 8 * small_page  # the control: ten times the content was written
    assert big_rss < small_rss + 16 * 1024 * 1024, peaks
