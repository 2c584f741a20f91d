"""The report page's small pieces: text as the page shows it, and each file's case blocks.

Every part of the page clips and escapes its text the same way (:func:`text`,
:func:`attr`), direction controls shown. The blocks of failed, flaky and other cases are
written into spools (``spool``, temporary files) as each result file is read, so the
page needs bounded memory however many cases there are and however many fail; the
timeline (``html_timeline``) and the page around them (``html_page``) are apart.
"""

from __future__ import annotations

from html import escape
from typing import NamedTuple

from ros_isolated_test.report.bounded_values import seconds_shown
from ros_isolated_test.report.counts import FileReport, listed_as_flaky, not_run_again
from ros_isolated_test.report.spool import Spool
from ros_isolated_test.text import shown, shown_code
from ros_isolated_test.xunit.model import Case, Outcome

#: The characters that set the direction of the text after them, shown as their code:
#: embeddings and overrides (U+202A-U+202E), isolates (U+2066-U+2069) and the marks
#: (U+200E, U+200F, U+061C). Drawn raw, one could make a test's name read as another's.
_DIRECTION_CONTROLS = {
    code: shown_code(code)
    for code in (*range(0x202A, 0x202F), *range(0x2066, 0x206A), 0x200E, 0x200F, 0x061C)
}
#: Characters of a message, a failure's text and an output tail shown per case.
MESSAGE_CHARS = 8 * 1024
TAIL_CHARS = 4 * 1024


#: A strip's letters, as ``history`` prints them, and what each says.
STRIP_LETTERS = {
    "P": "passed",
    "f": "passed after failing",
    "F": "failed",
    "E": "error",
    "T": "timed out",
    "S": "skipped",
    "N": "not run",
}


class Past(NamedTuple):
    """A test's runs before this one, from the test history.

    Plain data: the report sits below the history, which ``cli.report`` reads for it.
    ``kind`` is what a failure now is: ``new`` (no failure before), ``flaky`` (passed
    and failed before) or ``broken`` (failed in every run before, since ``since``).
    """

    kind: str
    #: One letter per run it was in, oldest first (:data:`STRIP_LETTERS`).
    strip: str
    #: Runs it was in, and those of them with a failed attempt.
    runs: int
    failing: int
    #: Broken: the first run of the streak, "run 4 (2026-11-29 06:04)".
    since: str = ""


def past_said(past: Past | None) -> str:
    """What a failure is, given the runs before: new, known flaky, or broken since when."""
    if past is None or past.kind == "new":
        before = f": passed its last {past.runs} run(s)" if past and past.runs else ""
        return f'<span class="known new">new{before}</span>'
    if past.kind == "broken":
        return f'<span class="known broken">broken since {text(past.since, 128)}</span>'
    return (
        f'<span class="known flaky">known flaky ({past.failing} of the last {past.runs} '
        "runs failed)</span>"
    )


def strip_html(past: Past | None, now: str) -> str:
    """The outcome strip: each run before (oldest first), then this one's letter ``now``."""
    cells = "".join(f'<i class="s{letter}">{letter}</i>' for letter in past.strip) if past else ""
    said = STRIP_LETTERS.get(now, now)
    runs = past.runs if past else 0
    title = (
        f"the {runs} run(s) before, oldest first, then this one ({said})"
        if runs
        else (f"not in the history before; this run: {said}")
    )
    return f'<span class=strip title="{attr(title)}">{cells}<i class="s{now} now">{now}</i></span>'


def text(value: str, limit: int, tail: bool = False) -> str:
    r"""``value`` cut to ``limit`` characters (its head, or its tail), escaped for HTML.

    Direction controls are shown as their code (``\u202e``), as the text report shows
    them: a name that reverses itself ("\u202egnissap\u202c") never reads as another.
    """
    value = shown(value).translate(_DIRECTION_CONTROLS)
    if len(value) > limit:
        cut = len(value) - limit
        if tail:
            value = f"[... {cut} characters before ...]\n{value[-limit:]}"
        else:
            value = f"{value[:limit]}\n[... {cut} more characters ...]"
    return escape(value, quote=False)


def attr(value: str) -> str:
    """``value`` as an attribute's text, escaped, its direction controls shown."""
    return escape(shown(value).translate(_DIRECTION_CONTROLS), quote=True)


def now_letter(case: Case) -> str:
    """The letter of a case's outcome in this run, last in its strip."""
    if case.outcome.failed:
        return "E" if case.outcome is Outcome.ERROR else "F"
    if case.attempts:
        return "f" if case.outcome is Outcome.PASSED else "S"
    return "S" if case.outcome is Outcome.SKIPPED else "P"


def write_case(
    spool: Spool,
    case: Case,
    anchor: str,
    test: str,
    where: str,
    suite_output: str,
    past: Past | None = None,
    history: bool = False,
) -> None:
    """A failed or flaky case: its message first, its text, the tail of its output.

    With a ``history``, what the runs before say of it (``past``: None when it is in
    none of them) and its outcome strip.
    """
    flaky = not case.outcome.failed
    if flaky:
        tag = "flaky"
        kind = "flaky" if case.outcome is Outcome.PASSED else "skipped after failing"
    elif not_run_again(case):
        tag, kind = "failure", "failed, then not run"
    else:
        tag, kind = case.outcome.value, case.outcome.value
    known = ""
    if history:
        known = f" {strip_html(past, now_letter(case))}"
        if not flaky:
            known = f" {past_said(past)}{known}"
    spool.write(
        f'<article class="case {"flaky" if flaky else "failed"}" id="{anchor}" '
        f'data-test="{attr(test)}" data-outcome="{tag}">'
        f'<h3><span class="tag {tag}">{escape(kind)}</span>{text(case.classname, 512)} '
        f"<b>{text(case.name, 512)}</b>{known}</h3>"
        f'<div class="where">in {text(test, 512)} · {where}</div>'
    )
    if flaky:
        after = "passed" if case.outcome is Outcome.PASSED else case.outcome.value
        spool.write(
            f"<p>{len(case.attempts)} failed attempt(s), then {after}:</p><ol class=attempts>"
        )
        for attempt in case.attempts:
            label = "error" if attempt.kind.endswith("Error") else "failure"
            spool.write(
                f"<li>{label}<pre class=message>{text(attempt.message, MESSAGE_CHARS)}</pre>"
            )
            _write_output(spool, attempt.system_out + attempt.system_err)
            spool.write("</li>")
        spool.write("</ol></article>")
        return
    message = case.message or "(no message)"
    spool.write(f"<pre class=message>{text(message, MESSAGE_CHARS)}</pre>")
    if case.text and case.text.strip() != case.message.strip():
        spool.write(f"<pre>{text(case.text, MESSAGE_CHARS)}</pre>")
    if case.attempts:
        spool.write(f"<p>{len(case.attempts)} earlier failed attempt(s):</p><ol class=attempts>")
        for attempt in case.attempts:
            spool.write(f"<li><pre>{text(attempt.message, 1024)}</pre></li>")
        spool.write("</ol>")
    output = case.system_out + case.system_err
    if not output and suite_output and suite_output not in message:
        output = suite_output
    _write_output(spool, output)
    spool.write("</article>")


def _write_output(spool: Spool, output: str) -> None:
    if output.strip():
        spool.write(
            "<details><summary>output (tail)</summary>"
            f"<pre>{text(output, TAIL_CHARS, tail=True)}</pre></details>"
        )


def write_suite(
    spool: Spool,
    anchor: str,
    test: str,
    where: str,
    report: FileReport,
    cases: list[Case],
    strips: tuple[str, dict[int, str]] = ("", {}),
) -> None:
    """A suite's block: its counts, then every case not listed above, by class.

    ``strips``: the outcome strip of the file's test (a runner's file is one test), and
    of each case by its index (pytest's items), as :func:`strip_html` draws them.
    """
    whole, of_case = strips
    said = [f"{report.tests} test(s)", f"{report.passed} passed"]
    if report.skipped:
        said.append(f"{report.skipped} skipped")
    if report.failed:
        said.append(f"{report.errors + report.failures} failed")
    if report.flaky:
        said.append(f"{report.flaky} flaky")
    spool.write(
        f'<details class="suite" id="{anchor}" data-test="{attr(test)}"><summary>'
        f"<b>{text(test, 512)}</b>{whole}<span class=counts>{', '.join(said)} · {where}</span>"
        "</summary>"
    )
    rest = [
        (index, case)
        for index, case in enumerate(cases)
        if not case.outcome.failed and not listed_as_flaky(case)
    ]
    if not rest:
        spool.write("<p class=none>every case is listed above</p></details>")
        return
    spool.write("<table class=cases>")
    group: str | None = None
    for index, case in rest:
        if case.classname != group:
            if group is not None:
                spool.write("</tbody>")
            group = case.classname
            spool.write(
                f'<tbody data-class="{attr(group)}"><tr class=cls>'
                f"<th colspan=3>{text(group, 512)}</th></tr>"
            )
        outcome = case.outcome.value
        note = ""
        if case.outcome is Outcome.SKIPPED and case.message:
            note = f": {text(case.message.splitlines()[0] if case.message else '', 200)}"
        spool.write(
            f'<tr class="c {outcome}"><td>{text(case.name, 512)}{of_case.get(index, "")}</td>'
            f"<td>{seconds_shown(case.time)}</td><td class=o>{outcome}{note}</td></tr>"
        )
    spool.write("</tbody></table></details>")
