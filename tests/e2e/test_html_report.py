"""``report --html``: the page a person opens after a run, read in real headless Chromium.

Six tests run at once through ``run`` on a pool of three free IDs (a lock directory of
the test's own): one fails with a known message, one is flaky (``--rerun-failures 1``),
one holds ``cpu=1`` of a set capacity. Each attempt waits at a gate (helpers/gate.py)
until this test has looked at ``status --json`` while it surely runs, so what status
recorded is known for every attempt, with no timing assumed; the first three are held
until the other three are seen queued, so some tests surely waited for an ID. Then
``report --html`` writes the page, Chromium opens it with every request going to a
counting proxy, and its DOM, after the page's scripts ran, must show every test, the
message, the flaky test as flaky, one bar per attempt (seven), no two bars at once on
one ID, the bars where status saw each test, and no request made. A screenshot is kept
as a CI artifact (tests/artifacts/html_report/report.png).
"""

from __future__ import annotations

import itertools
import json
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from helpers import capabilities, chromium, gate
from helpers.chromium import with_class as cls
from helpers.commands import run_cli, start_cli
from helpers.domains import free_ids
from helpers.processes import poll_until
from lxml import html

pytestmark = [capabilities.CHROMIUM.mark]

PACKAGE = "demo"
#: Each test's name: how it ends, and the options of its ``run``.
TESTS: dict[str, tuple[str, tuple[str, ...]]] = {
    "talker": ("pass", ()),
    "listener": ("pass", ()),
    "fails": ("fail", ()),
    "flaky": ("flaky", ("--rerun-failures", "1")),
    "heavy": ("pass", ("--resources", "cpu=1")),
    "quiet": ("pass", ()),
}
GATE = Path(gate.__file__)
ARTIFACT = chromium.ARTIFACTS / "html_report" / "report.png"


@dataclass
class Snapshot:
    """One ``status --json``, taken between ``before`` and ``after`` (``time.time()``)."""

    before: float
    after: float
    #: Domain ID -> the test whose runner holds it (our runners only).
    holders: dict[int, str]
    #: Tests whose runners wait in the queue.
    queued: set[str]
    #: Test -> the resources its runner holds.
    holds: dict[str, dict[str, int]]


@dataclass
class Run:
    """What the six tests did, what status said meanwhile, and the page of it."""

    ids: list[int]
    results: Path
    #: (test, attempt) -> the snapshot taken while that attempt waited at its gate.
    seen: dict[tuple[str, int], Snapshot] = field(default_factory=dict)
    #: The snapshot that showed the other three queued.
    queue: Snapshot | None = None
    codes: dict[str, int] = field(default_factory=dict)
    page: Path | None = None
    report_code: int = 0
    report_out: str = ""


def _test_of(command: object, gates: Path) -> str | None:
    match = re.search(rf"{re.escape(str(gates))} (\w+) ", str(command))
    return match.group(1) if match else None


def _snapshot(env: dict[str, str], gates: Path) -> Snapshot:
    before = time.time()
    proc = run_cli(["status", "--json"], env)
    after = time.time()
    assert proc.returncode == 0, proc.stderr
    holders: dict[int, str] = {}
    queued: set[str] = set()
    holds: dict[str, dict[str, int]] = {}
    for row in json.loads(proc.stdout):
        test = _test_of(row.get("command"), gates)
        if test is None:
            continue  # another process on this machine
        if row["via"] == "lock":
            holders[row["domain_id"]] = test
        elif row["via"] == "queue":
            queued.add(test)
        elif row["via"] == "hold":
            holds[test] = row["resources"]
    return Snapshot(before, after, holders, queued, holds)


def _three_queued(env: dict[str, str], gates: Path) -> Snapshot:
    """Once three tests run (at their gates), the snapshot that shows the other three queued."""
    poll_until(lambda: len(list(gates.glob("*.ready.*"))) >= 3, "three tests running")
    taken: list[Snapshot] = []

    def queued() -> bool:
        taken.append(_snapshot(env, gates))
        return len(taken[-1].queued) == 3

    poll_until(queued, "the other three tests queued for an ID")
    return taken[-1]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory, module_env: dict[str, str]) -> Run:
    """The six tests at once on three IDs, status looked at for every attempt, the page."""
    root = tmp_path_factory.mktemp("html_run")
    ids = free_ids(3)
    env = {
        **module_env,
        "ROS_ISOLATED_TEST_DOMAINS": ",".join(map(str, ids)),
        "ROS_ISOLATED_TEST_CAPACITY": "cpu=1",
    }
    gates, results = root / "gates", root / "results"
    gates.mkdir()
    found = Run(ids, results)
    started: list[subprocess.Popen[bytes]] = []
    try:
        processes = {
            name: start_cli(
                [
                    "run",
                    "--junit-xml",
                    str(results / f"{name}.xml"),
                    "--package-name",
                    PACKAGE,
                    *options,
                    "--",
                    sys.executable,
                    str(GATE),
                    str(gates),
                    name,
                    how,
                ],
                env,
                root / f"{name}.log",
                started,
            )
            for name, (how, options) in TESTS.items()
        }
        released: set[str] = set()
        while any(process.poll() is None for process in processes.values()):
            ready = sorted(path.name for path in gates.glob("*.ready.*"))
            waiting = [name for name in ready if name not in released]
            if not waiting:
                time.sleep(0.02)
                continue
            if found.queue is None:
                # Hold the first three at their gates until the others are seen queued.
                found.queue = _three_queued(env, gates)
                waiting = sorted(path.name for path in gates.glob("*.ready.*"))
            for name in waiting:
                test, _, attempt = name.split(".")
                found.seen[(test, int(attempt))] = _snapshot(env, gates)
                (gates / f"{test}.go.{attempt}").touch()
                released.add(name)
        found.codes = {name: process.wait() for name, process in processes.items()}
    finally:
        for process in started:
            if process.poll() is None:
                process.kill()
    found.page = root / "report.html"
    # Relative paths, as in CI: the page (and the README's screenshot) names no tmp folder.
    proc = run_cli(["report", "--html", found.page.name, results.name], env, cwd=root)
    found.report_code, found.report_out = proc.returncode, proc.stdout + proc.stderr
    return found


@pytest.fixture(scope="module")
def dom(run: Run) -> html.HtmlElement:
    assert run.page is not None and run.page.is_file(), run.report_out
    return chromium.dump_dom(run.page)


def _bars(dom: html.HtmlElement) -> list[html.HtmlElement]:
    return list(dom.xpath(f"//*[@id='timeline']//a[{cls('bar')}]"))


def _span(bar: html.HtmlElement) -> tuple[float, float]:
    return float(bar.get("data-start")), float(bar.get("data-end"))


def test_the_run_ended_as_each_test_was_meant_to(run: Run) -> None:
    """The scene the page shows: one failure, a flaky pass, every attempt seen by status."""
    expected = {name: 1 if how == "fail" else 0 for name, (how, _) in TESTS.items()}
    assert run.codes == expected
    assert set(run.seen) == {*((name, 1) for name in TESTS), ("flaky", 2)}
    assert run.report_code == 1, run.report_out  # the text report and its exit code stay
    assert "Summary: 6 tests, 0 errors, 1 failures, 0 skipped" in run.report_out


def test_every_test_is_named_with_its_message_and_the_flaky_one_marked(
    dom: html.HtmlElement,
) -> None:
    root = dom.getroottree().getroot()
    assert root.get("data-drawn-ms"), "the page's script did not run to the end"
    named = {element.get("data-test") for element in dom.xpath(f"//details[{cls('suite')}]")}
    assert named == {f"{PACKAGE}.{name}" for name in TESTS}
    for name in TESTS:
        (summary,) = dom.xpath(f"//details[@data-test='{PACKAGE}.{name}']/summary")
        assert name in summary.text_content()
    (failed,) = dom.xpath(f"//section[@id='failures']//article[{cls('case')}]")
    assert failed.get("data-test") == f"{PACKAGE}.fails"
    assert gate.FAILURE in failed.xpath(f".//pre[{cls('message')}]")[0].text_content()
    (flaky,) = dom.xpath(f"//section[@id='flaky']//article[{cls('case')}]")
    assert flaky.get("data-test") == f"{PACKAGE}.flaky"
    assert "flaky" in flaky.get("class").split()
    assert flaky.xpath(f".//*[{cls('tag')}]")[0].text_content() == "flaky"
    earlier = flaky.xpath(f".//ol[{cls('attempts')}]//pre[{cls('message')}]")
    assert gate.FAILURE in earlier[0].text_content()
    assert "FAILED" in dom.xpath("//header//h1")[0].text_content()


def test_a_bar_per_attempt_and_never_two_at_once_on_one_id(run: Run, dom: html.HtmlElement) -> None:
    bars = _bars(dom)
    assert len(bars) == 7
    per_test = {
        name: [b for b in bars if b.get("data-test") == f"{PACKAGE}.{name}"] for name in TESTS
    }
    assert {name: len(found) for name, found in per_test.items()} == {
        name: 2 if name == "flaky" else 1 for name in TESTS
    }
    states = {(b.get("data-test"), b.get("data-attempt")): b.get("data-state") for b in bars}
    assert states[(f"{PACKAGE}.fails", "1")] == "failed"
    assert states[(f"{PACKAGE}.flaky", "1")] == "flaky"
    assert states[(f"{PACKAGE}.flaky", "2")] == "passed"
    assert min(_span(bar)[0] for bar in bars) == 0.0  # seconds from the earliest start
    by_domain: dict[str, list[tuple[float, float]]] = {}
    for bar in bars:
        assert int(bar.get("data-domain")) in run.ids
        by_domain.setdefault(bar.get("data-domain"), []).append(_span(bar))
    for domain, spans in by_domain.items():
        spans.sort()
        for (_, end), (start, _) in itertools.pairwise(spans):
            assert end <= start, f"two bars overlap on ID {domain}: {spans}"
    rows = dom.xpath(f"//*[@id='timeline']//div[{cls('trow')}]")
    assert {row.get("data-row") for row in rows} == {f"ID {d}" for d in by_domain}
    assert not [row for row in rows if "clash" in row.get("class").split()]


def test_the_timeline_matches_what_status_recorded_while_the_tests_ran(
    run: Run, dom: html.HtmlElement
) -> None:
    (timeline,) = dom.xpath("//*[@id='timeline']")
    t0 = float(timeline.get("data-t0"))
    bars = {
        (b.get("data-test").split(".", 1)[1], int(b.get("data-attempt"))): b for b in _bars(dom)
    }
    snapshots = [*run.seen.values(), *([run.queue] if run.queue else [])]
    for (test, attempt), snapshot in run.seen.items():
        bar = bars[(test, attempt)]
        start, end = (t0 + value for value in _span(bar))
        # Status saw the attempt's runner hold the bar's ID, within the bar's time.
        assert snapshot.holders.get(int(bar.get("data-domain"))) == test
        assert start <= snapshot.before and snapshot.after <= end
    for snapshot in snapshots:
        for (test, _), bar in bars.items():
            start, end = (t0 + value for value in _span(bar))
            if start <= snapshot.before and snapshot.after <= end:
                # A bar spanning a look at status: its runner held that ID then.
                assert snapshot.holders.get(int(bar.get("data-domain"))) == test
        for domain, test in snapshot.holders.items():
            assert any(
                key[0] == test and int(bar.get("data-domain")) == domain
                for key, bar in bars.items()
            ), f"status saw {test} on ID {domain}; no bar says so"
    # Those seen queued waited for an ID, drawn before their bar.
    assert run.queue is not None and len(run.queue.queued) == 3
    for test in run.queue.queued:
        bar = bars[(test, 1)]
        assert float(bar.get("data-wait-domain")) > 0
        waits = timeline.xpath(f".//div[{cls('domain')} and @data-test='{PACKAGE}.{test}']")
        assert waits and float(waits[0].get("data-seconds")) > 0
    # What the cpu=1 test held, as status showed it, is named on its bar.
    held = {test for snapshot in snapshots for test, what in snapshot.holds.items() if what}
    assert held == {"heavy"}
    assert bars[("heavy", 1)].get("data-resources") == "cpu=1"
    assert "held cpu=1" in bars[("heavy", 1)].get("title")
    pool = dom.xpath("//*[@id='fact-domain-pool']")[0].text_content()
    assert all(str(domain) in pool for domain in run.ids)
    assert dom.xpath("//*[@id='fact-capacity']")[0].text_content().startswith("cpu=1")


def test_the_page_makes_no_request(run: Run, tmp_path: Path) -> None:
    """Counted at a proxy every request goes to; the control page's requests are seen."""
    assert run.page is not None
    text = run.page.read_text(encoding="utf-8")
    assert chromium.external_references(text) == []
    counter = chromium.RequestCounter()
    try:
        chromium.dump_dom(run.page, counter)
        assert counter.page_requests() == []
        control = tmp_path / "control.html"
        control.write_text(
            '<!DOCTYPE html><html><head><link rel=stylesheet href="https://fonts.googleapis.com/'
            'css?family=Roboto"></head><body><img src="http://example.invalid/x.png"></body></html>'
        )
        assert len(chromium.external_references(control.read_text())) == 2
        chromium.dump_dom(control, counter)
        asked = {chromium.host_of(line) for line in counter.page_requests()}
        assert asked == {"fonts.googleapis.com", "example.invalid"}
    finally:
        counter.close()


def test_the_filter_box_keeps_the_tests_it_names(run: Run) -> None:
    """Set from the link (``#filter=``), as typing sets it: the rest is hidden or dimmed."""
    assert run.page is not None
    dom = chromium.dump_dom(run.page, fragment="#filter=listen")

    def hidden(element: html.HtmlElement) -> bool:
        return "hidden" in (element.get("class") or "").split()

    suites = {s.get("data-test"): hidden(s) for s in dom.xpath(f"//details[{cls('suite')}]")}
    assert suites == {f"{PACKAGE}.{name}": name != "listener" for name in TESTS}
    assert all(hidden(article) for article in dom.xpath("//article"))  # fails, flaky
    dimmed = {b.get("data-test"): "dim" in b.get("class").split() for b in _bars(dom)}
    assert dimmed == {f"{PACKAGE}.{name}": name != "listener" for name in TESTS}
    # Control: without a filter nothing is hidden or dimmed.
    plain = chromium.dump_dom(run.page)
    assert not [s for s in plain.xpath(f"//details[{cls('suite')}]") if hidden(s)]
    assert not [b for b in _bars(plain) if "dim" in b.get("class").split()]


def test_a_screenshot_is_kept_as_an_artifact(run: Run) -> None:
    assert run.page is not None
    chromium.screenshot(run.page, ARTIFACT, size=(1400, 1300))
    assert ARTIFACT.read_bytes().startswith(b"\x89PNG")
