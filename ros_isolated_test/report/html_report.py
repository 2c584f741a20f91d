"""``report --html``: one self-contained page for a tree of result files, with a timeline.

Viewers of result files show cases; none can say why a suite was slow or flaky. The
runner records when each attempt ran, on which domain ID, what it waited for first and
what it held (``result_file.STARTED_AT`` and its neighbours), and this page draws it:
one bar per attempt on a time axis, one row per domain ID (per host and ID when the
files come from several machines), the wait before each bar. Above it the totals and
the run's facts; below it failures and errors first with their message and output
tail, then flaky cases with each attempt, then everything else by package and suite.

Self-contained (inline style and script, a policy that forbids any request), so it
works as a CI artifact opened offline. Written as a stream in bounded memory, however
many cases there are and however many fail: each file's cases go straight into one of
three spools and are forgotten; only counts, a few distinct facts and one small record
per attempt are kept. The page is then put together from the spools, so the totals
come first although they are known last. Every value drawn is read within bounds
(``bounded_values``): an odd one is named on the page, never a crash or a hang.

The page is made in four modules: this one reads each file into the page (``write``,
the flow), ``html_timeline`` turns attempts into bars and draws them, ``html_parts``
writes each case and suite into the spools, ``html_page`` keeps the page's state and
puts it together; ``html_assets`` is the inline style and script. The printed report
is made from the same reading (``write``'s ``each``): every file is read once.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO

from ros_isolated_test import names
from ros_isolated_test.atomic_file import NotReplaceableError, discards, special_kind
from ros_isolated_test.report import html_timeline
from ros_isolated_test.report.bounded_values import Reading, drawable
from ros_isolated_test.report.counts import FileReport, listed_as_flaky
from ros_isolated_test.report.html_page import FACTS, Page, assemble
from ros_isolated_test.report.html_parts import (
    Past,
    now_letter,
    strip_html,
    text,
    write_case,
    write_suite,
)
from ros_isolated_test.report.html_timeline import BAR_TEXT
from ros_isolated_test.report.shard import Split
from ros_isolated_test.report.shard_durations import named_tests
from ros_isolated_test.report.tree import FileRead, read_tree
from ros_isolated_test.text import shown
from ros_isolated_test.xunit import raw
from ros_isolated_test.xunit.canonical import test_name_of
from ros_isolated_test.xunit.model import Case
from ros_isolated_test.xunit.xml_text import name_token


def write(
    paths: Iterable[Path],
    destination: Path,
    each: Callable[[FileRead], object] | None = None,
    split: Split | None = None,
    history: tuple[str, dict[str, Past]] | None = None,
) -> FileReport:
    """Write the page for every result file under ``paths`` to ``destination``.

    Each file, once read into the page, is handed to ``each`` (the printed report) and
    forgotten; returns the counts of them all. ``destination`` is replaced whole in one
    rename (a reader never sees half a page); the null device discards it; a device
    node, FIFO or socket is never replaced (:class:`NotReplaceableError`, before
    anything is read). ``split`` gathers what the trees say of a split (each file and
    the machines' records), which the page shows with its problems. ``history`` is what
    the test history says of the runs before this one (where it is kept, and each
    test's :class:`Past` by identity): each failure then says whether it is new, known
    flaky or broken since when, and each test shows its outcome strip.
    """
    discard = discards(destination)
    kind = None if discard else special_kind(destination)
    if kind is not None:
        raise NotReplaceableError(destination, kind)
    if not discard and destination.is_dir():
        raise IsADirectoryError(21, "it is a directory", str(destination))
    page = Page()
    if history is not None:
        page.history_source, page.history = history
    records: list[Path] = []
    try:
        for number, item in enumerate(read_tree(paths, records), start=1):
            _add(page, item, number)
            if split is not None:
                split.add(item)
            if each is not None:
                each(item)
        if split is not None:
            split.add_records(records)
            page.shares, page.split_problems = split.shares(), split.problems
        if not discard:
            with _replacing(destination) as out:
                assemble(page, out)
    finally:
        page.close()
    return page.total


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


def _add(page: Page, item: FileRead, number: int) -> None:
    """Read one result file into the page: its cases into the spools, its bars kept."""
    report, cases, read = item.report, item.cases, item.read
    page.total.include(report)
    where = _shown_path(item.path)
    if read is None:  # a folder that could not be read: its one error case
        for index, case in enumerate(cases, start=1):
            write_case(page.failures, case, f"f{number}-{index}", where, where, "")
        return
    page.files += 1
    suite = read.suites[0] if read.suites else None
    properties = suite.properties if suite is not None else {}
    ours = names.RUNNER_VERSION in properties and len(read.suites) == 1
    page.foreign += not ours
    test = suite.name if ours and suite is not None and suite.name else test_name_of(item.path)
    package = _package_of(item.path, test, ours)
    host = _host_of(read)
    page.note("host", host)
    if ours:  # other producers record none of these: they are counted apart
        for fact, name, _ in FACTS[1:]:
            page.note(fact, properties.get(name or "", ""))
    failed = [case for case in cases if case.outcome.failed]
    flaky = [case for case in cases if listed_as_flaky(case)]
    # A click on the test's bar leads to its first failure, else its first flaky case.
    target = f"f{number}-1" if failed else f"k{number}-1" if flaky else f"s{number}"
    reading = Reading()
    bars = html_timeline.bars_of(properties, read, test, host, report, target, reading)
    long = [case for case in cases if not drawable(case.time)]
    if long:
        first = long[0]
        reading.name(
            f"time of {len(long)} case(s), the first {first.classname} {first.name}",
            f"{first.time:g}",
            "over a week: shown as unknown (a time in milliseconds?)",
        )
    page.name_odd(where, reading.odd)
    page.attempts += len(bars)
    page.bars.extend(bars)
    where += html_timeline.runs(bars)
    output = suite.system_out if suite is not None else ""
    past_of = _pasts(page, item, ours)
    on = page.history is not None
    for index, case in enumerate(failed, start=1):
        past = past_of(case)
        write_case(page.failures, case, f"f{number}-{index}", test, where, output, past, on)
    for index, case in enumerate(flaky, start=1):
        past = past_of(case)
        write_case(page.flaky, case, f"k{number}-{index}", test, where, output, past, on)
    offset = page.rest.size
    strips = _strips(page, item, ours, past_of)
    write_suite(page.rest, f"s{number}", test, _shown_path(item.path), report, cases, strips)
    listed = len(failed) + len(flaky)
    block = (package[:BAR_TEXT], test[:BAR_TEXT], number, offset, page.rest.size - offset)
    page.blocks.append((*block, len(cases), listed))


def _pasts(page: Page, item: FileRead, ours: bool) -> Callable[[Case], Past | None]:
    """Each case's test in the history before this run: a runner's file is one test."""
    history = page.history
    if history is None:
        return lambda case: None
    if ours:
        named = named_tests(item)
        past = history.get(named[0][0]) if len(named) == 1 else None
        return lambda case: past
    identities = _identities(item)
    if not identities:
        return lambda case: None
    return lambda case: history.get(identities.get((case.classname, case.name), ""))


def _identities(item: FileRead) -> dict[tuple[str, str], str]:
    """Each item's identity by (class name, name) as the page names it (pytest's items)."""
    if item.read is None:
        return {}
    return {
        (
            name_token(raw.attrs.get("classname", ""), "").rstrip(".") or raw.suite.strip(),
            name_token(raw.attrs.get("name", ""), ""),
        ): raw.identity
        for raw in item.read.cases
        if raw.identity
    }


def _strips(
    page: Page, item: FileRead, ours: bool, past_of: Callable[[Case], Past | None]
) -> tuple[str, dict[int, str]]:
    """The outcome strips of a suite's block: the file's one test, or each item's."""
    if page.history is None:
        return "", {}
    if ours:
        report = item.report
        exit_text = item.read.suites[0].properties.get("exit", "") if item.read else ""
        letter = "P"
        if "timed out" in exit_text:
            letter = "T"
        elif exit_text == "not run":
            letter = "N"
        elif report.failed:
            letter = "E" if report.errors and not report.failures else "F"
        elif report.flaky:
            letter = "f"
        elif report.tests and report.skipped == report.tests:
            letter = "S"
        whole = past_of(item.cases[0]) if item.cases else None
        return f" {strip_html(whole, letter)}", {}
    named = _identities(item)  # an item the history may know: its strip, if only this run
    strips: dict[int, str] = {}
    for index, case in enumerate(item.cases):
        if (case.classname, case.name) in named:
            strips[index] = f" {strip_html(past_of(case), now_letter(case))}"
    return "", strips


def _package_of(path: Path, test: str, ours: bool) -> str:
    """The package: colcon's ``test_results/<package>/`` folder, else our suite's prefix."""
    if path.parent.parent.name == "test_results" and path.parent.name:
        return shown(path.parent.name)
    if ours and "." in test:
        return test.split(".", 1)[0]
    return shown(path.parent.name) or "(no package)"


def _host_of(read: raw.ReadResult) -> str:
    for attrs in [suite.attrs for suite in read.suites] + [read.root_attrs]:
        if attrs.get("hostname"):
            return attrs["hostname"]
    return ""


def _shown_path(path: Path) -> str:
    return text(str(path), 1024)
