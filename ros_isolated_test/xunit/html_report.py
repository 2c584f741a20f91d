"""``report --html``: one self-contained page for a tree of result files, with a timeline.

Viewers of result files show cases; none can say why a suite was slow or flaky. The
runner records when each attempt ran, on which domain ID, what it waited for first and
what it held (``result_file.STARTED_AT`` and its neighbours), and this page draws it:
one bar per attempt on a time axis, one row per domain ID (per host and ID when the
files come from several machines), the wait before each bar. Above it the totals and
the run's facts; below it failures and errors first with their message and output
tail, then flaky cases with each attempt, then everything else by package and suite.

Self-contained (inline style and script, a policy that forbids any request), so it
works as a CI artifact opened offline. Written as a stream in bounded memory: each
file's cases go straight into one of three spools and are forgotten; only counts, a
few distinct facts and one small record per attempt are kept. The page is then put
together from the spools, so the totals come first although they are known last.
"""

from __future__ import annotations

import contextlib
import datetime
import math
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator
from html import escape
from pathlib import Path
from typing import IO

from ros_isolated_test import __version__
from ros_isolated_test.atomic_file import NotReplaceableError, discards, special_kind
from ros_isolated_test.text import shown
from ros_isolated_test.xunit import html_assets, normalise, reader
from ros_isolated_test.xunit.attempts import ATTEMPTS_PROPERTY, NOT_RUN_AGAIN_TYPE
from ros_isolated_test.xunit.model import Case, Outcome
from ros_isolated_test.xunit.report import FileReport, counted, result_files, unreadable_folder
from ros_isolated_test.xunit.result_file import (
    DOMAIN_POOL,
    ENDED_AT,
    STARTED_AT,
    WAIT_DOMAIN,
    WAIT_RESOURCES,
    test_name_of,
)

#: Characters of a message, a failure's text and an output tail shown per case.
MESSAGE_CHARS = 8 * 1024
TAIL_CHARS = 4 * 1024
#: Distinct values kept per fact (hosts, pools, ...); more are counted.
FACT_VALUES = 12
#: Timestamps before this are a producer's placeholder (gtest writes 1970-01-01).
_PLAUSIBLE = datetime.datetime(2000, 1, 1, tzinfo=datetime.timezone.utc).timestamp()
_COPY_CHUNK = 1 << 20
#: The facts of the run, as the header's table names them, and the property of each.
_FACTS = (
    ("host", None),
    ("domain pool", DOMAIN_POOL),
    ("capacity", "capacity"),
    ("discovery range", "ros_discovery_range"),
    ("runner version", "runner_version"),
)


class Bar:
    """One attempt of one test on the timeline; times in seconds since the epoch."""

    __slots__ = (
        "attempt",
        "attempts",
        "domain",
        "end",
        "host",
        "resources",
        "start",
        "state",
        "target",
        "test",
        "wait_domain",
        "wait_resources",
    )

    def __init__(
        self,
        test: str,
        host: str,
        domain: str,
        start: float,
        end: float,
        state: str,
        target: str,
        attempt: int = 1,
        attempts: int = 1,
        wait_domain: float = 0.0,
        wait_resources: float = 0.0,
        resources: str = "",
    ) -> None:
        self.test = test
        self.host = host
        #: The ID as the result says it ("17"); "" when the test had none of ours.
        self.domain = domain
        self.start = start
        self.end = max(end, start)
        #: passed, failed, flaky (a failed attempt of a test that passed in the end),
        #: timeout or skipped: the bar's colour.
        self.state = state
        #: Where a click on the bar leads: the test's failure, flaky case or suite.
        self.target = target
        self.attempt = attempt
        self.attempts = attempts
        self.wait_domain = wait_domain
        self.wait_resources = wait_resources
        self.resources = resources


class Page:
    """What the page needs once every file is read: counts, facts, bars, spools."""

    def __init__(self) -> None:
        self.reports: list[FileReport] = []
        self.bars: list[Bar] = []
        self.facts: dict[str, dict[str, int]] = {name: {} for name, _ in _FACTS}
        self.files = 0
        self.foreign = 0
        self.attempts = 0
        # Spools: failures and errors, flaky cases, the rest (suite blocks, indexed).
        self.failures = _Spool()
        self.flaky = _Spool()
        self.rest = _Spool()
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


class _Spool:
    """A temporary file written as UTF-8 that knows its length: a part of the page."""

    def __init__(self) -> None:
        self.file: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115 (closed by Page.close)
        self.size = 0

    def write(self, text: str) -> None:
        data = text.encode("utf-8", "backslashreplace")
        self.file.write(data)
        self.size += len(data)

    def copy_to(self, out: IO[bytes], offset: int = 0, length: int | None = None) -> None:
        """Bytes ``offset`` to ``offset + length`` (default: to the end) into ``out``."""
        self.file.flush()
        self.file.seek(offset)
        left = self.size - offset if length is None else length
        while left > 0:
            chunk = self.file.read(min(left, _COPY_CHUNK))
            if not chunk:
                break
            out.write(chunk)
            left -= len(chunk)
        self.file.seek(0, os.SEEK_END)

    def close(self) -> None:
        self.file.close()


def write(paths: Iterable[Path], destination: Path) -> list[FileReport]:
    """Write the page for every result file under ``paths`` to ``destination``.

    Returns each file's report, as :func:`report.reports` gives them, for the text
    report and the exit code. ``destination`` is replaced whole in one rename (a
    reader never sees half a page); the null device discards it; a device node, FIFO
    or socket is never replaced (:class:`NotReplaceableError`, before anything is read).
    """
    discard = discards(destination)
    kind = None if discard else special_kind(destination)
    if kind is not None:
        raise NotReplaceableError(destination, kind)
    if not discard and destination.is_dir():
        raise IsADirectoryError(21, "it is a directory", str(destination))
    page = Page()
    try:
        for number, item in enumerate(result_files(paths), start=1):
            if isinstance(item, OSError):
                _add_unreadable(page, unreadable_folder(item), number)
            else:
                _add_file(page, item, number)
        if discard:
            return page.reports
        with _replacing(destination) as out:
            _assemble(page, out)
    finally:
        page.close()
    return page.reports


@contextlib.contextmanager
def _replacing(destination: Path) -> Iterator[IO[bytes]]:
    """A new file beside ``destination`` that replaces it once written whole."""
    folder = destination.parent
    folder.mkdir(parents=True, exist_ok=True)
    handle = tempfile.NamedTemporaryFile(  # noqa: SIM115 (renamed or removed below)
        dir=folder, prefix=f".{destination.name}.", suffix=".tmp", delete=False
    )
    try:
        with handle:
            yield handle
            os.fchmod(handle.fileno(), 0o644)
        kind = special_kind(destination)  # one that appeared while the page was written
        if kind is not None:
            raise NotReplaceableError(destination, kind)
        os.replace(handle.name, destination)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(handle.name)
        raise


# -- reading ---------------------------------------------------------------------------


def _add_unreadable(page: Page, report: FileReport, number: int) -> None:
    page.reports.append(report)
    where = _shown_path(report.path)
    for index, case in enumerate(report.failed_cases, start=1):
        _write_case(page.failures, case, f"f{number}-{index}", where, where, "")


def _add_file(page: Page, path: Path, number: int) -> None:
    """Read one result file into the page: its cases into the spools, its bars kept."""
    read = reader.read(path)
    if read.root_tag is not None and not read.is_xunit:
        return  # XML that is no test result (a ctest Test.xml), as ``report`` skips it
    cases = normalise.cases_from(read, None, test_name_of(path))
    report = counted(path, cases)
    page.reports.append(report)
    page.files += 1
    suite = read.suites[0] if read.suites else None
    properties = suite.properties if suite is not None else {}
    ours = "runner_version" in properties and len(read.suites) == 1
    page.foreign += not ours
    test = suite.name if ours and suite is not None and suite.name else test_name_of(path)
    package = _package_of(path, test, ours)
    host = _host_of(read)
    page.note("host", host or "(not recorded)")
    for fact, name in _FACTS[1:]:
        if name is not None and properties.get(name):
            page.note(fact, properties[name])
    # A click on the test's bar leads to its first failure, else its first flaky case.
    target = f"f{number}-1" if report.failed_cases else f"k{number}-1" if report.flaky else ""
    bars = _bars(properties, read, test, host, report, target or f"s{number}")
    page.attempts += len(bars)
    page.bars.extend(bars)
    where = f"{_shown_path(path)}{_runs(bars)}"
    output = suite.system_out if suite is not None else ""
    for index, case in enumerate(report.failed_cases, start=1):
        _write_case(page.failures, case, f"f{number}-{index}", test, where, output)
    for index, case in enumerate(report.flaky_cases, start=1):
        _write_case(page.flaky, case, f"k{number}-{index}", test, where, output)
    listed = len(report.failed_cases) + len(report.flaky_cases)
    offset = page.rest.size
    _write_suite(page.rest, f"s{number}", test, _shown_path(path), report, cases)
    page.blocks.append((package, test, number, offset, page.rest.size - offset, len(cases), listed))


def _runs(bars: list[Bar]) -> str:
    """Where each attempt ran and how it ended: which attempt of a flaky test failed where."""
    said = []
    for bar in bars:
        where = f" on ID {bar.domain}" if bar.domain else ""
        which = f"attempt {bar.attempt} " if bar.attempts > 1 else ""
        state = "failed" if bar.state == "flaky" else _STATE_WORDS.get(bar.state, bar.state)
        said.append(f"{which}{state}{where}, {bar.end - bar.start:.2f} s")
    return "".join(f"<br>{escape(line)}" for line in said)


def _package_of(path: Path, test: str, ours: bool) -> str:
    """The package: colcon's ``test_results/<package>/`` folder, else our suite's prefix."""
    if path.parent.parent.name == "test_results" and path.parent.name:
        return shown(path.parent.name)
    if ours and "." in test:
        return test.split(".", 1)[0]
    return shown(path.parent.name) or "(no package)"


def _host_of(read: reader.ReadResult) -> str:
    for attrs in [suite.attrs for suite in read.suites] + [read.root_attrs]:
        if attrs.get("hostname"):
            return attrs["hostname"]
    return ""


def _bars(
    properties: dict[str, str],
    read: reader.ReadResult,
    test: str,
    host: str,
    report: FileReport,
    target: str,
) -> list[Bar]:
    """The file's attempts on the timeline: each one the runner recorded.

    A file that does not say (another producer's, an older runner's) gets one bar from
    its own timestamp and time, when it has a plausible one.
    """
    final = _final_state(properties.get("exit", ""), report)
    if STARTED_AT not in properties:
        span = _producer_span(read)
        if span is None:
            return []
        domain = _domain(properties, "")
        return [Bar(test, host, domain, span[0], span[1], final, target)]
    total = _number(properties.get(ATTEMPTS_PROPERTY, "1"), 1)
    bars: list[Bar] = []
    for attempt in range(1, total + 1):
        prefix = "" if attempt == total else f"attempt_{attempt}."
        if prefix and f"{prefix}{STARTED_AT}" not in properties:
            continue  # not kept (a long series keeps the first and last few)

        def value(name: str, prefix: str = prefix) -> str:
            return properties.get(f"{prefix}{name}", properties.get(name, ""))

        start = _instant(value(STARTED_AT))
        if start is None:
            continue
        end = _instant(value(ENDED_AT)) or start
        if prefix:
            failed = "timeout" if "timed out" in value("exit") else "failed"
            state = failed if report.failed or failed == "timeout" else "flaky"
        else:
            state = final
        bars.append(
            Bar(
                test,
                host,
                _domain(properties, prefix),
                start,
                end,
                state,
                target,
                attempt,
                total,
                _seconds(value(WAIT_DOMAIN)),
                _seconds(value(WAIT_RESOURCES)),
                value("resources"),
            )
        )
    return bars


def _final_state(exit_reason: str, report: FileReport) -> str:
    if "timed out" in exit_reason:
        return "timeout"
    if report.failed:
        return "failed"
    if report.tests and report.skipped == report.tests:
        return "skipped"
    return "passed"


def _domain(properties: dict[str, str], prefix: str) -> str:
    """The attempt's domain ID as a number's text; "" without one of ours (isolation off)."""
    if properties.get("isolation") == "disabled":
        return ""
    value = properties.get(f"{prefix}ros_domain_id", properties.get("ros_domain_id", ""))
    return value if value.isascii() and value.isdigit() else ""


def _producer_span(read: reader.ReadResult) -> tuple[float, float] | None:
    """When a producer's own file says it ran: its earliest plausible timestamp and time."""
    start: float | None = None
    end = 0.0
    for attrs in [suite.attrs for suite in read.suites] + [read.root_attrs]:
        began = _instant(attrs.get("timestamp", ""))
        if began is None or began < _PLAUSIBLE:
            continue
        start = began if start is None else min(start, began)
        end = max(end, began + _seconds(attrs.get("time", "")))
    return None if start is None else (start, max(end, start))


def _instant(text: str) -> float | None:
    """ISO 8601 as seconds since the epoch; a time without a zone is local time."""
    text = text.strip()
    if not text:
        return None
    if text.endswith(("Z", "z")):
        text = text[:-1] + "+00:00"
    try:
        return datetime.datetime.fromisoformat(text).timestamp()
    except (ValueError, OverflowError, OSError):
        return None


def _seconds(text: str) -> float:
    try:
        value = float(text.replace(",", ""))
    except ValueError:
        return 0.0
    return value if math.isfinite(value) and value > 0 else 0.0


def _number(text: str, default: int) -> int:
    return int(text) if text.isascii() and text.isdigit() and int(text) > 0 else default


# -- writing the parts -------------------------------------------------------------------


def _text(value: str, limit: int, tail: bool = False) -> str:
    """``value`` cut to ``limit`` characters (its head, or its tail), escaped for HTML."""
    value = shown(value)
    if len(value) > limit:
        cut = len(value) - limit
        if tail:
            value = f"[... {cut} characters before ...]\n{value[-limit:]}"
        else:
            value = f"{value[:limit]}\n[... {cut} more characters ...]"
    return escape(value, quote=False)


def _attr(value: str) -> str:
    return escape(shown(value), quote=True)


def _write_case(
    spool: _Spool, case: Case, anchor: str, test: str, where: str, suite_output: str
) -> None:
    """A failed or flaky case: its message first, its text, the tail of its output."""
    flaky = not case.outcome.failed
    if flaky:
        tag, kind = "flaky", "flaky"
    elif case.type == NOT_RUN_AGAIN_TYPE:
        tag, kind = "failure", "failed, then not run"
    else:
        tag, kind = case.outcome.value, case.outcome.value
    spool.write(
        f'<article class="case {"flaky" if flaky else "failed"}" id="{anchor}" '
        f'data-test="{_attr(test)}" data-outcome="{tag}">'
        f'<h3><span class="tag {tag}">{escape(kind)}</span>{_text(case.classname, 512)} '
        f"<b>{_text(case.name, 512)}</b></h3>"
        f'<div class="where">in {_text(test, 512)} · {where}</div>'
    )
    if flaky:
        after = "passed" if case.outcome is Outcome.PASSED else case.outcome.value
        spool.write(
            f"<p>{len(case.attempts)} failed attempt(s), then {after}:</p><ol class=attempts>"
        )
        for attempt in case.attempts:
            label = "error" if attempt.kind.endswith("Error") else "failure"
            spool.write(
                f"<li>{label}<pre class=message>{_text(attempt.message, MESSAGE_CHARS)}</pre>"
            )
            _write_output(spool, attempt.system_out + attempt.system_err)
            spool.write("</li>")
        spool.write("</ol></article>")
        return
    message = case.message or "(no message)"
    spool.write(f"<pre class=message>{_text(message, MESSAGE_CHARS)}</pre>")
    if case.text and case.text.strip() != case.message.strip():
        spool.write(f"<pre>{_text(case.text, MESSAGE_CHARS)}</pre>")
    if case.attempts:
        spool.write(f"<p>{len(case.attempts)} earlier failed attempt(s):</p><ol class=attempts>")
        for attempt in case.attempts:
            spool.write(f"<li><pre>{_text(attempt.message, 1024)}</pre></li>")
        spool.write("</ol>")
    output = case.system_out + case.system_err
    if not output and suite_output and suite_output not in message:
        output = suite_output
    _write_output(spool, output)
    spool.write("</article>")


def _write_output(spool: _Spool, output: str) -> None:
    if output.strip():
        spool.write(
            "<details><summary>output (tail)</summary>"
            f"<pre>{_text(output, TAIL_CHARS, tail=True)}</pre></details>"
        )


def _write_suite(
    spool: _Spool, anchor: str, test: str, where: str, report: FileReport, cases: list[Case]
) -> None:
    """A suite's block: its counts, then every case not listed above, by class."""
    listed = len(report.failed_cases) + len(report.flaky_cases)
    said = [f"{report.tests} test(s)", f"{report.tests - listed - report.skipped} passed"]
    if report.skipped:
        said.append(f"{report.skipped} skipped")
    if report.failed:
        said.append(f"{report.errors + report.failures} failed")
    if report.flaky:
        said.append(f"{report.flaky} flaky")
    spool.write(
        f'<details class="suite" id="{anchor}" data-test="{_attr(test)}"><summary>'
        f"<b>{_text(test, 512)}</b><span class=counts>{', '.join(said)} · {where}</span>"
        "</summary>"
    )
    rest = [case for case in cases if not case.outcome.failed and not case.flaky]
    if not rest:
        spool.write("<p class=none>every case is listed above</p></details>")
        return
    spool.write("<table class=cases>")
    group: str | None = None
    for case in rest:
        if case.classname != group:
            if group is not None:
                spool.write("</tbody>")
            group = case.classname
            spool.write(
                f'<tbody data-class="{_attr(group)}"><tr class=cls>'
                f"<th colspan=3>{_text(group, 512)}</th></tr>"
            )
        outcome = case.outcome.value
        note = ""
        if case.outcome is Outcome.SKIPPED and case.message:
            note = f": {_text(case.message.splitlines()[0] if case.message else '', 200)}"
        spool.write(
            f'<tr class="c {outcome}"><td>{_text(case.name, 512)}</td>'
            f"<td>{case.time:.3f} s</td><td class=o>{outcome}{note}</td></tr>"
        )
    spool.write("</tbody></table></details>")


def _shown_path(path: Path) -> str:
    return _text(str(path), 1024)


# -- the page ----------------------------------------------------------------------------


def _assemble(page: Page, out: IO[bytes]) -> None:
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
    put(_timeline_html(page.bars))
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
    for fact, _ in _FACTS:
        values = page.facts[fact]
        shown_values = [
            f"{_text(value, 256)}" + (f" ({count} files)" if len(values) > 1 else "")
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
            f"<tr><th>ran</th><td>{escape(_local(first))} to {escape(_local(last))} "
            f"({last - first:.1f} s)</td></tr>"
        )
    if page.foreign:
        rows.append(
            f"<tr><th>other producers</th><td>{page.foreign} result file(s) not written by "
            "ros-isolated-test (listed; on the timeline where they carry a timestamp)</td></tr>"
        )
    rows.append(
        f"<tr><th>page</th><td>ros-isolated-test {escape(__version__)}, "
        f"{escape(_local(datetime.datetime.now().timestamp()))}</td></tr>"
    )
    return f"<h2>Run</h2><table class=facts>{''.join(rows)}</table>"


def _local(when: float) -> str:
    return datetime.datetime.fromtimestamp(when).astimezone().isoformat(timespec="seconds")


_STATES = (
    ("passed", "passed"),
    ("failed", "failed"),
    ("flaky", "failed, passed later (flaky)"),
    ("timeout", "timed out"),
    ("skipped", "skipped"),
    ("wait", "waiting for an ID"),
    ("waitres", "waiting for resources"),
)


def _timeline_html(bars: list[Bar]) -> str:
    """The bars, one row per (host, domain ID), lanes only where bars overlap in a row."""
    legend = "".join(f"<span><i class=k-{key}></i>{escape(text)}</span>" for key, text in _STATES)
    head = f"<h2>Timeline</h2><div class=legend>{legend}</div>"
    if not bars:
        return head + "<p class=none>No result file says when it ran: nothing to draw.</p>"
    t0 = min(bar.start for bar in bars)
    low = min(bar.start - bar.wait_domain - bar.wait_resources for bar in bars)
    high = max(bar.end for bar in bars)
    span = max(high - low, 1e-3)
    # A file that names no host (other producers') is on the one host, when there is one.
    hosts = {bar.host for bar in bars if bar.host}
    several = len(hosts) > 1
    rows: dict[tuple[str, int, str], list[Bar]] = {}
    for bar in bars:
        key = (bar.host if several else "", 0 if bar.domain else 1, bar.domain.zfill(4))
        rows.setdefault(key, []).append(bar)

    def pos(when: float) -> str:
        return f"{(when - low) / span * 100:.4f}%"

    def place(begin: float, end: float) -> str:
        return f"left:{pos(begin)};width:{(end - begin) / span * 100:.4f}%"

    parts = [
        head,
        f'<div id=timeline data-t0="{t0:.6f}" data-low="{low - t0:.6f}" '
        f'data-high="{high - t0:.6f}" data-hosts="{len(hosts)}"><div class=tgrid>',
    ]
    for tick in _ticks(low - t0, high - t0):
        # A label at the right edge would be cut: its line alone says enough.
        label = _tick_label(tick) if (t0 + tick - low) / span < 0.95 else ""
        parts.append(f'<div class=tick style="left:{pos(t0 + tick)}"><span>{label}</span></div>')
    parts.append("</div><div class=taxis></div>")
    for (host, _, _), members in sorted(rows.items()):
        members.sort(key=lambda bar: (bar.start, bar.end))
        lanes: list[float] = []
        placed: list[tuple[Bar, int]] = []
        for bar in members:
            lane = next((i for i, end in enumerate(lanes) if end <= bar.start), len(lanes))
            if lane == len(lanes):
                lanes.append(bar.end)
            else:
                lanes[lane] = bar.end
            placed.append((bar, lane))
        domain = members[0].domain
        name = f"ID {domain}" if domain else "no domain ID"
        if several:
            name = f"{host or '(host not recorded)'} · {name}"
        clash = " clash" if domain and len(lanes) > 1 else ""
        title = " (used by two tests at once)" if clash else ""
        parts.append(
            f'<div class="trow{clash}" data-row="{_attr(name)}" data-host="{_attr(host)}" '
            f'data-domain="{_attr(domain)}"><div class=tlabel title="{_attr(name + title)}">'
            f'{_text(name, 128)}</div><div class=tlane style="--lanes:{len(lanes)}">'
        )
        for bar, lane in placed:
            parts.append(_bar_html(bar, lane, t0, span, place))
        parts.append("</div></div>")
    parts.append(f"</div><p class=where>0 s = {escape(_local(t0))}, the earliest start.</p>")
    return "".join(parts)


def _bar_html(
    bar: Bar, lane: int, t0: float, span: float, place: Callable[[float, float], str]
) -> str:
    """The bar of one attempt, after the wait before it (for an ID, then for resources)."""
    card = _card(bar, t0)
    common = f'data-test="{_attr(bar.test)}" data-domain="{_attr(bar.domain)}"'
    parts = []
    waited = bar.wait_domain + bar.wait_resources
    if waited > 0:
        begin = bar.start - waited
        for kind, seconds in (("domain", bar.wait_domain), ("resources", bar.wait_resources)):
            if seconds <= 0:
                continue
            parts.append(
                f'<div class="wait {kind}" {common} data-seconds="{seconds:.3f}" '
                f'style="{place(begin, begin + seconds)};--lane:{lane}" '
                f'title="{_attr(card)}" data-card="{_attr(card)}"></div>'
            )
            begin += seconds
    short = bar.test.split(".", 1)[1] if "." in bar.test else bar.test
    label = short if bar.attempts == 1 else f"{short} ({bar.attempt}/{bar.attempts})"
    # A bar too narrow for its name keeps it for tools and the hover card, not drawn.
    narrow = " narrow" if (bar.end - bar.start) / span < 0.03 else ""
    parts.append(
        f'<a class="bar {bar.state}{narrow}" href="#{bar.target}" {common} '
        f'data-start="{bar.start - t0:.6f}" data-end="{bar.end - t0:.6f}" '
        f'data-state="{bar.state}" data-attempt="{bar.attempt}" data-attempts="{bar.attempts}" '
        f'data-host="{_attr(bar.host)}" data-resources="{_attr(bar.resources)}" '
        f'data-wait-domain="{bar.wait_domain:.3f}" data-wait-resources="{bar.wait_resources:.3f}" '
        f'style="{place(bar.start, bar.end)};--lane:{lane}" title="{_attr(card)}" '
        f'data-card="{_attr(card)}">{_text(label, 256)}</a>'
    )
    return "".join(parts)


_STATE_WORDS = {
    "passed": "passed",
    "failed": "failed",
    "flaky": "failed (the test passed in a later attempt)",
    "timeout": "timed out",
    "skipped": "skipped",
}


def _card(bar: Bar, t0: float) -> str:
    """What hovering a bar says: the test, the attempt, where, how long, what it held."""
    lines = [bar.test]
    attempt = f"attempt {bar.attempt} of {bar.attempts}: " if bar.attempts > 1 else ""
    lines.append(f"{attempt}{_STATE_WORDS.get(bar.state, bar.state)}")
    where = f"ROS_DOMAIN_ID {bar.domain}" if bar.domain else "no domain ID of ours"
    if bar.host:
        where += f" on {bar.host}"
    lines.append(where)
    lines.append(f"ran {bar.end - bar.start:.2f} s, from +{bar.start - t0:.2f} s")
    if bar.wait_domain or bar.wait_resources:
        lines.append(
            f"waited {bar.wait_domain:.2f} s for an ID, {bar.wait_resources:.2f} s for resources"
        )
    lines.append(f"held {bar.resources}" if bar.resources else "held no resources")
    return "\n".join(lines)


_CLOCK_STEPS = (60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400)


def _ticks(low: float, high: float) -> list[float]:
    """Round times between ``low`` and ``high``: about eight of them."""
    span = max(high - low, 1e-3)
    raw = span / 8
    magnitude = 10 ** math.floor(math.log10(raw))
    step = next(m * magnitude for m in (1, 2, 5, 10) if m * magnitude >= raw)
    if step > 30:  # minutes and hours, not 50000 s
        step = next((clock for clock in _CLOCK_STEPS if clock >= raw), step)
    first = math.ceil(low / step) * step
    count = int((high - first) / step) + 1
    return [first + i * step for i in range(max(count, 0))]


def _tick_label(seconds: float) -> str:
    """``-2 s``, ``1.5 s``, ``2 min 30 s``, ``3 h 20 min``: what an axis of that span needs."""
    sign = "-" if seconds < 0 else ""
    value = abs(seconds)
    if value < 120:
        return f"{sign}{value:.3f}".rstrip("0").rstrip(".") + " s"
    if value < 7200:
        minutes, rest = divmod(round(value), 60)
        return f"{sign}{minutes} min" + (f" {rest} s" if rest else "")
    hours, rest = divmod(round(value / 60), 60)
    return f"{sign}{hours} h" + (f" {rest} min" if rest else "")


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
            f'<details class=pkg open data-package="{_attr(package)}"><summary>'
            f"{_text(package, 256)}<span class=counts>{len(members)} suite(s), "
            f"{tests} test(s)</span></summary>"
        )
        for _suite, _number, offset, length, _tests, _listed in members:
            page.rest.copy_to(out, offset, length)
        put("</details>")
