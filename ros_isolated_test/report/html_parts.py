"""The report page's small pieces: text as the page shows it, and each file's case blocks.

Every part of the page clips and escapes its text the same way (:func:`text`,
:func:`attr`) and gives times in local time (:func:`local`). The blocks of failed, flaky
and other cases are written into spools (:class:`Spool`, temporary files) as each result
file is read, so the page needs bounded memory however many cases there are; the
timeline (``html_timeline``) and the page around them (``html_page``) are apart.
"""

from __future__ import annotations

import datetime
import os
import tempfile
from html import escape
from typing import IO

from ros_isolated_test.report.counts import FileReport
from ros_isolated_test.text import shown
from ros_isolated_test.xunit.attempts import NOT_RUN_AGAIN_TYPE
from ros_isolated_test.xunit.model import Case, Outcome

#: Characters of a message, a failure's text and an output tail shown per case.
MESSAGE_CHARS = 8 * 1024
TAIL_CHARS = 4 * 1024
_COPY_CHUNK = 1 << 20


def text(value: str, limit: int, tail: bool = False) -> str:
    """``value`` cut to ``limit`` characters (its head, or its tail), escaped for HTML."""
    value = shown(value)
    if len(value) > limit:
        cut = len(value) - limit
        if tail:
            value = f"[... {cut} characters before ...]\n{value[-limit:]}"
        else:
            value = f"{value[:limit]}\n[... {cut} more characters ...]"
    return escape(value, quote=False)


def attr(value: str) -> str:
    return escape(shown(value), quote=True)


def local(when: float) -> str:
    return datetime.datetime.fromtimestamp(when).astimezone().isoformat(timespec="seconds")


class Spool:
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


def write_case(
    spool: Spool, case: Case, anchor: str, test: str, where: str, suite_output: str
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
        f'data-test="{attr(test)}" data-outcome="{tag}">'
        f'<h3><span class="tag {tag}">{escape(kind)}</span>{text(case.classname, 512)} '
        f"<b>{text(case.name, 512)}</b></h3>"
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
    spool: Spool, anchor: str, test: str, where: str, report: FileReport, cases: list[Case]
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
        f'<details class="suite" id="{anchor}" data-test="{attr(test)}"><summary>'
        f"<b>{text(test, 512)}</b><span class=counts>{', '.join(said)} · {where}</span>"
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
                f'<tbody data-class="{attr(group)}"><tr class=cls>'
                f"<th colspan=3>{text(group, 512)}</th></tr>"
            )
        outcome = case.outcome.value
        note = ""
        if case.outcome is Outcome.SKIPPED and case.message:
            note = f": {text(case.message.splitlines()[0] if case.message else '', 200)}"
        spool.write(
            f'<tr class="c {outcome}"><td>{text(case.name, 512)}</td>'
            f"<td>{case.time:.3f} s</td><td class=o>{outcome}{note}</td></tr>"
        )
    spool.write("</tbody></table></details>")
