"""The report page's timeline: one bar per attempt, where and when it ran, drawn on a time axis.

Read from what the runner records in each result file (``result_file.STARTED_AT`` and
its neighbours: when each attempt ran, on which domain ID, what it waited for first and
what it held), or from another producer's own timestamp; then placed in rows per (machine,
domain ID), lanes only where bars overlap, and a round-numbered axis. A machine is a host,
or a share of a split on it (``shard 2/4 · host``): the machines of a split's merged
trees each get their group of rows, even when they share a host name. Apart from the
rest of the page because this is the one part that reasons about time and placement.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from html import escape

from ros_isolated_test import names
from ros_isolated_test.report.bounded_values import LONGEST, Reading, local
from ros_isolated_test.report.counts import FileReport
from ros_isolated_test.report.html_parts import attr, text
from ros_isolated_test.shard.selection import SHARD_PROPERTY
from ros_isolated_test.xunit import raw
from ros_isolated_test.xunit.attempts import ATTEMPTS_PROPERTY
from ros_isolated_test.xunit.timeline import ENDED_AT, STARTED_AT, WAIT_DOMAIN, WAIT_RESOURCES

#: The highest domain ID drawn as one (ROS 2 allows up to 232 on Linux).
MAX_DOMAIN_ID = 232
#: Characters a bar keeps of its test's name, host and resources: the page shows fewer,
#: and a bar is kept for every attempt until the page is put together.
BAR_TEXT = 512


class Bar:
    """One attempt of one test on the timeline; times in seconds since the epoch."""

    __slots__ = (
        "attempt",
        "attempts",
        "domain",
        "end",
        "host",
        "machine",
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
        attempts: int = 1,  # 0: unknown (the file's count could not be read)
        wait_domain: float = 0.0,
        wait_resources: float = 0.0,
        resources: str = "",
        machine: str | None = None,
    ) -> None:
        self.test = test[:BAR_TEXT]
        self.host = host[:BAR_TEXT]
        #: Where it ran, as its group of rows says it: the host, or ``shard I/N · host``.
        self.machine = (host if machine is None else machine)[:BAR_TEXT]
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
        self.resources = resources[:BAR_TEXT]


def bars_of(
    properties: dict[str, str],
    read: raw.ReadResult,
    test: str,
    host: str,
    report: FileReport,
    target: str,
    reading: Reading,
) -> list[Bar]:
    """The file's attempts on the timeline: each one the runner recorded and kept.

    A file that does not say (another producer's, an older runner's) gets one bar from
    its own timestamp and time, when it has a plausible one. Every value is read within
    bounds (``reading``): one that cannot be drawn is named there, never computed with.
    """
    final = _final_state(properties.get(names.EXIT, ""), report)
    machine = machine_of(properties, host)
    if STARTED_AT not in properties:
        span = _producer_span(read, reading)
        if span is None:
            return []
        domain = _domain(properties, "", reading)
        return [Bar(test, host, domain, span[0], span[1], final, target, machine=machine)]
    said = properties.get(ATTEMPTS_PROPERTY, "").strip()
    total = reading.count(ATTEMPTS_PROPERTY, said) if said else 1
    # Only the attempts the file kept (a long series keeps the first and last few): the
    # count is never looped over, so no value makes this take long.
    earlier = _earlier_attempts(properties)
    last = total if total is not None else max(earlier, default=0) + 1
    bars: list[Bar] = []
    for attempt in [number for number in earlier if number < last] + [last]:
        prefix = "" if attempt == last else f"attempt_{attempt}."
        bar = _bar(properties, prefix, reading)
        if bar is None:
            continue
        start, end, waits = bar
        if prefix:
            failed = "timeout" if "timed out" in _value(properties, prefix, "exit") else "failed"
            state = failed if report.failed or failed == "timeout" else "flaky"
        else:
            state = final
        bars.append(
            Bar(
                test,
                host,
                _domain(properties, prefix, reading),
                start,
                end,
                state,
                target,
                attempt,
                total or 0,
                waits[0],
                waits[1],
                _value(properties, prefix, "resources"),
                machine,
            )
        )
    return bars


def machine_of(properties: dict[str, str], host: str) -> str:
    """The machine a result ran on: ``shard 2/4 · host`` in a split, else the host."""
    share = properties.get(SHARD_PROPERTY, "").strip()
    return " · ".join(filter(None, (f"shard {share}" if share else "", host)))


def _value(properties: dict[str, str], prefix: str, name: str) -> str:
    """An attempt's property: its own (``attempt_<k>.<name>``), else the last attempt's."""
    return properties.get(f"{prefix}{name}", properties.get(name, ""))


def _earlier_attempts(properties: dict[str, str]) -> list[int]:
    """The numbers ``k`` of the ``attempt_<k>.started_at`` the file holds, in order."""
    found = set()
    for key in properties:
        if key.startswith("attempt_") and key.endswith(f".{STARTED_AT}"):
            number = key[len("attempt_") : -len(STARTED_AT) - 1]
            if number.isascii() and number.isdigit() and len(number) <= 4 and int(number) > 0:
                found.add(int(number))
    return sorted(found)


def _bar(
    properties: dict[str, str], prefix: str, reading: Reading
) -> tuple[float, float, tuple[float, float]] | None:
    """An attempt's start, end and waits (for an ID, for resources), each within bounds."""
    start = reading.instant(f"{prefix}{STARTED_AT}", _value(properties, prefix, STARTED_AT))
    if start is None:
        return None
    end = reading.instant(f"{prefix}{ENDED_AT}", _value(properties, prefix, ENDED_AT))
    if end is None:
        end = start
    elif end < start or end - start > LONGEST:
        reading.name(
            f"{prefix}{ENDED_AT}",
            _value(properties, prefix, ENDED_AT),
            "before its start or over a week after it: drawn as no time",
        )
        end = start
    waits = tuple(
        reading.seconds(f"{prefix}{name}", _value(properties, prefix, name)) or 0.0
        for name in (WAIT_DOMAIN, WAIT_RESOURCES)
    )
    return start, end, (waits[0], waits[1])


def _final_state(exit_reason: str, report: FileReport) -> str:
    if "timed out" in exit_reason:
        return "timeout"
    if report.failed:
        return "failed"
    if report.tests and report.skipped == report.tests:
        return "skipped"
    return "passed"


def _domain(properties: dict[str, str], prefix: str, reading: Reading) -> str:
    """The attempt's domain ID as a number's text; "" without one of ours (isolation off)."""
    if properties.get(names.ISOLATION_PROPERTY) == "disabled":
        return ""
    value = _value(properties, prefix, "ros_domain_id")
    if not value:
        return ""
    if value.isascii() and value.isdigit() and len(value) <= 3 and int(value) <= MAX_DOMAIN_ID:
        return str(int(value))
    reading.name(f"{prefix}ros_domain_id", value, f"not a domain ID (0 to {MAX_DOMAIN_ID})")
    return ""


def _producer_span(read: raw.ReadResult, reading: Reading) -> tuple[float, float] | None:
    """When a producer's own file says it ran: its earliest drawable timestamp and time."""
    start: float | None = None
    end = 0.0
    for attrs in [suite.attrs for suite in read.suites] + [read.root_attrs]:
        stamp = attrs.get("timestamp", "")
        if stamp.startswith("1970-01-01"):
            continue  # gtest's placeholder: no time said
        began = reading.instant("timestamp", stamp)
        if began is None:
            continue
        start = began if start is None else min(start, began)
        end = max(end, began + (reading.seconds("time", attrs.get("time", "")) or 0.0))
    return None if start is None else (start, max(end, start))


def runs(bars: list[Bar]) -> str:
    """Where each attempt ran and how it ended: which attempt of a flaky test failed where."""
    said = []
    for bar in bars:
        where = f" on ID {bar.domain}" if bar.domain else ""
        which = f"attempt {bar.attempt} " if bar.attempts != 1 else ""
        state = "failed" if bar.state == "flaky" else _STATE_WORDS.get(bar.state, bar.state)
        said.append(f"{which}{state}{where}, {bar.end - bar.start:.2f} s")
    return "".join(f"<br>{escape(line)}" for line in said)


_STATES = (
    ("passed", "passed"),
    ("failed", "failed"),
    ("flaky", "failed, passed later (flaky)"),
    ("timeout", "timed out"),
    ("skipped", "skipped"),
    ("wait", "waiting for an ID"),
    ("waitres", "waiting for resources"),
)


def timeline_html(bars: list[Bar]) -> str:
    """The bars, one row per (host, domain ID), lanes only where bars overlap in a row."""
    parts: list[str] = []
    write_timeline(bars, parts.append)
    return "".join(parts)


def write_timeline(bars: list[Bar], put: Callable[[str], object]) -> None:
    """:func:`timeline_html` written piece by piece: a page of many bars is never one string."""
    legend = "".join(f"<span><i class=k-{key}></i>{escape(text)}</span>" for key, text in _STATES)
    head = f"<h2>Timeline</h2><div class=legend>{legend}</div>"
    if not bars:
        put(head + "<p class=none>No result file says when it ran: nothing to draw.</p>")
        return
    t0 = min(bar.start for bar in bars)
    low = min(bar.start - bar.wait_domain - bar.wait_resources for bar in bars)
    high = max(bar.end for bar in bars)
    span = max(high - low, 1e-3)
    # A file that names no host (other producers') is on the one host, when there is one.
    hosts = {bar.host for bar in bars if bar.host}
    machines = {bar.machine for bar in bars if bar.machine}
    several = len(machines) > 1
    rows: dict[tuple[str, int, str], list[Bar]] = {}
    for bar in bars:
        key = (bar.machine if several else "", 0 if bar.domain else 1, bar.domain.zfill(4))
        rows.setdefault(key, []).append(bar)

    def pos(when: float) -> str:
        return f"{(when - low) / span * 100:.4f}%"

    def place(begin: float, end: float) -> str:
        return f"left:{pos(begin)};width:{(end - begin) / span * 100:.4f}%"

    put(head)
    put(
        f'<div id=timeline data-t0="{t0:.6f}" data-low="{low - t0:.6f}" '
        f'data-high="{high - t0:.6f}" data-hosts="{len(hosts)}" '
        f'data-machines="{len(machines)}"><div class=tgrid>'
    )
    for tick in _ticks(low - t0, high - t0):
        # A label at the right edge would be cut: its line alone says enough.
        label = _tick_label(tick) if (t0 + tick - low) / span < 0.95 else ""
        put(f'<div class=tick style="left:{pos(t0 + tick)}"><span>{label}</span></div>')
    put("</div><div class=taxis></div>")
    for (machine, _, _), members in sorted(rows.items()):
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
            name = f"{machine or '(host not recorded)'} · {name}"
        clash = " clash" if domain and len(lanes) > 1 else ""
        title = " (used by two tests at once)" if clash else ""
        host = members[0].host if several else ""
        put(
            f'<div class="trow{clash}" data-row="{attr(name)}" data-host="{attr(host)}" '
            f'data-machine="{attr(machine)}" data-domain="{attr(domain)}">'
            f'<div class=tlabel title="{attr(name + title)}">'
            f'{text(name, 128)}</div><div class=tlane style="--lanes:{len(lanes)}">'
        )
        for bar, lane in placed:
            put(_bar_html(bar, lane, t0, span, place))
        put("</div></div>")
    put(f"</div><p class=where>0 s = {escape(local(t0))}, the earliest start.</p>")


def _bar_html(
    bar: Bar, lane: int, t0: float, span: float, place: Callable[[float, float], str]
) -> str:
    """The bar of one attempt, after the wait before it (for an ID, then for resources)."""
    card = _card(bar, t0)
    common = f'data-test="{attr(bar.test)}" data-domain="{attr(bar.domain)}"'
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
                f'title="{attr(card)}" data-card="{attr(card)}"></div>'
            )
            begin += seconds
    short = bar.test.split(".", 1)[1] if "." in bar.test else bar.test
    label = short if bar.attempts == 1 else f"{short} ({bar.attempt}/{_of(bar)})"
    # A bar too narrow for its name keeps it for tools and the hover card, not drawn.
    narrow = " narrow" if (bar.end - bar.start) / span < 0.03 else ""
    parts.append(
        f'<a class="bar {bar.state}{narrow}" href="#{bar.target}" {common} '
        f'data-start="{bar.start - t0:.6f}" data-end="{bar.end - t0:.6f}" '
        f'data-state="{bar.state}" data-attempt="{bar.attempt}" data-attempts="{_of(bar)}" '
        f'data-host="{attr(bar.host)}" data-resources="{attr(bar.resources)}" '
        f'data-wait-domain="{bar.wait_domain:.3f}" data-wait-resources="{bar.wait_resources:.3f}" '
        f'style="{place(bar.start, bar.end)};--lane:{lane}" title="{attr(card)}" '
        f'data-card="{attr(card)}">{text(label, 256)}</a>'
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
    attempt = f"attempt {bar.attempt} of {_of(bar)}: " if bar.attempts != 1 else ""
    lines.append(f"{attempt}{_STATE_WORDS.get(bar.state, bar.state)}")
    where = f"ROS_DOMAIN_ID {bar.domain}" if bar.domain else "no domain ID of ours"
    if bar.machine:
        where += f" on {bar.machine}"
    lines.append(where)
    lines.append(f"ran {bar.end - bar.start:.2f} s, from +{bar.start - t0:.2f} s")
    if bar.wait_domain or bar.wait_resources:
        lines.append(
            f"waited {bar.wait_domain:.2f} s for an ID, {bar.wait_resources:.2f} s for resources"
        )
    lines.append(f"held {bar.resources}" if bar.resources else "held no resources")
    return "\n".join(lines)


def _of(bar: Bar) -> str:
    """How many attempts the test had, as the page says it ("unknown": not readable)."""
    return str(bar.attempts) if bar.attempts else "unknown"


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
