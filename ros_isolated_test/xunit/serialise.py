"""Canonical xUnit bytes from a :class:`~ros_isolated_test.xunit.model.Suite`.

A serializer of one fixed shape, on the standard library only: every test's runner
writes a result file, and loading lxml for that would cost it more than all the rest of
its own work. Escaping lives in :func:`attribute` and :func:`text`, the only two places
a value enters the document; the layout matches lxml's ``pretty_print`` output, and the
test suite parses and validates what this writes against ``schemas/junit.xsd``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from ros_isolated_test import __version__, names
from ros_isolated_test.xunit.gitlab import written_type
from ros_isolated_test.xunit.model import Attempt, Case, Outcome, Suite
from ros_isolated_test.xunit.xml_text import TEXT_LIMIT, name_token, xml_safe

DECLARATION = "<?xml version='1.0' encoding='UTF-8'?>\n"
# Tabs and line ends in an attribute would come back as spaces (attribute-value
# normalisation), and a CR in text as LF: written as character references, they survive.
_ATTRIBUTE = str.maketrans(
    {
        "&": "&amp;",
        "<": "&lt;",
        ">": "&gt;",
        '"': "&quot;",
        "\n": "&#10;",
        "\r": "&#13;",
        "\t": "&#9;",
    }
)
_TEXT = str.maketrans({"&": "&amp;", "<": "&lt;", ">": "&gt;", "\r": "&#13;"})
#: The line :func:`flaky_note` opens a flaky pass's output with, however it is worded.
_FLAKY_NOTE = re.compile(
    r"\APassed after [0-9]+ failed attempt\(s\); [^\n]{0,80}recorded below\.\n?"
)


def attribute(value: str) -> str:
    """A legal-XML value escaped for a double-quoted attribute."""
    return value.translate(_ATTRIBUTE)


def text(value: str) -> str:
    """A legal-XML value escaped for element content."""
    return value.translate(_TEXT)


def _seconds(value: float) -> str:
    return f"{max(value, 0.0):.3f}"


def _start(tag: str, attributes: Iterable[tuple[str, str]]) -> str:
    pairs = "".join(f' {name}="{attribute(value)}"' for name, value in attributes)
    return f"<{tag}{pairs}"


def _output(lines: list[str], indent: str, out: str, err: str) -> None:
    for tag, value in (("system-out", out), ("system-err", err)):
        safe = xml_safe(value, TEXT_LIMIT)
        if safe.strip():
            lines.append(f"{indent}<{tag}>{text(safe)}</{tag}>\n")


def _attempt(lines: list[str], attempt: Attempt) -> None:
    """An earlier attempt, as Surefire writes it: the text in ``<stackTrace>``.

    junit-10 requires ``type``: a producer that gave none gets the outcome's name.
    """
    from ros_isolated_test.xunit.attempts import ATTEMPT_TEXT_LIMIT

    message = xml_safe(attempt.message, ATTEMPT_TEXT_LIMIT)
    fallback = "error" if attempt.kind.endswith("Error") else "failure"
    head = _start(
        attempt.kind, (("message", message), ("type", written_type(attempt.type, fallback)))
    )
    body: list[str] = []
    trace = xml_safe(attempt.text, ATTEMPT_TEXT_LIMIT) or message
    for tag, value in (
        ("stackTrace", trace),
        ("system-out", xml_safe(attempt.system_out, ATTEMPT_TEXT_LIMIT)),
        ("system-err", xml_safe(attempt.system_err, ATTEMPT_TEXT_LIMIT)),
    ):
        if value.strip():
            body.append(f"        <{tag}>{text(value)}</{tag}>\n")
    if body:
        lines.extend((f"      {head}>\n", *body, f"      </{attempt.kind}>\n"))
    else:
        lines.append(f"      {head}/>\n")


def flaky_note(system_out: str, failed: int, shown: int) -> str:
    """A flaky pass's output, opened by one line saying so (once, however often re-read).

    ``failed`` attempts failed and ``shown`` of them are written (:func:`kept`: the oldest
    and newest halves). A note already there (the file read back) is replaced, not added
    to, so a canonical file normalised again is unchanged.
    """
    if shown >= failed:
        which = "each is"
    else:
        head = shown // 2
        which = f"the first {head} and the last {shown - head} are"
    note = f"Passed after {failed} failed attempt(s); {which} recorded below."
    rest = _FLAKY_NOTE.sub("", system_out, count=1)
    return f"{note}\n{rest}" if rest.strip() else note


def _case(lines: list[str], case: Case) -> None:
    head = _start(
        "testcase",
        (
            ("classname", name_token(case.classname, "unnamed")),
            ("name", name_token(case.name, "unnamed")),
            ("time", _seconds(case.time)),
        ),
    )
    body: list[str] = []
    if case.outcome is not Outcome.PASSED:
        message = xml_safe(case.message, TEXT_LIMIT)
        attributes = [("message", message)]
        kind = written_type(case.type)
        if kind:
            attributes.append(("type", kind))
        content = xml_safe(case.text, TEXT_LIMIT) or message
        tag = case.outcome.value
        outcome = _start(tag, attributes)
        body.append(
            f"      {outcome}>{text(content)}</{tag}>\n" if content else f"      {outcome}/>\n"
        )
    attempts: list[Attempt] = []
    if case.attempts:  # reruns only: a test run once never loads their rules
        from ros_isolated_test.xunit.attempts import attempt_count, kept

        attempts = kept(case.attempts)
    if case.outcome is Outcome.PASSED and attempts:
        # The output first: xunit-viewer takes a case's status from its first child.
        note = flaky_note(case.system_out, attempt_count(case.attempts), len(attempts))
        _output(body, "      ", note, "")
        for attempt in attempts:
            _attempt(body, attempt)
        _output(body, "      ", "", case.system_err)
    else:
        for attempt in attempts:
            _attempt(body, attempt)
        _output(body, "      ", case.system_out, case.system_err)
    if body:
        lines.extend((f"    {head}>\n", *body, "    </testcase>\n"))
    else:
        lines.append(f"    {head}/>\n")


def serialize(suite: Suite) -> bytes:
    """The ``<testsuites>`` document of one suite, counts recomputed from its cases."""
    name = name_token(suite.name, "ros_isolated_test.result")
    counts = (
        ("tests", str(len(suite.cases))),
        ("failures", str(suite.count(Outcome.FAILURE))),
        ("errors", str(suite.count(Outcome.ERROR))),
    )
    skipped = ("skipped", str(suite.count(Outcome.SKIPPED)))
    duration = ("time", _seconds(suite.time))
    lines = [
        DECLARATION,
        _start("testsuites", (("name", name), *counts, duration)) + ">\n",
        "  "
        + _start(
            "testsuite",
            (
                ("name", name),
                *counts,
                skipped,
                duration,
                ("timestamp", suite.timestamp),
                ("hostname", name_token(suite.hostname, "localhost", 255)),
            ),
        )
        + ">\n",
        "    <properties>\n",
    ]
    for key, value in {**suite.properties, names.RUNNER_VERSION: __version__}.items():
        pair = (("name", name_token(key, "property")), ("value", xml_safe(value, 4096)))
        lines.append(f"      {_start('property', pair)}/>\n")
    lines.append("    </properties>\n")
    for case in suite.cases:
        _case(lines, case)
    _output(lines, "    ", suite.system_out, suite.system_err)
    lines.append("  </testsuite>\n</testsuites>\n")
    return "".join(lines).encode("utf-8")
