"""The result file: canonical xUnit XML built, checked against our schema, and written.

Built with lxml's element API (never string templates), so escaping is right by
construction. Every document is validated against ``schemas/junit.xsd`` and its counts
re-checked before it is written; one that fails is a bug of ours, and is written as a
valid file that says so instead of being lost.
"""

from __future__ import annotations

import contextlib
import os
import socket
import stat
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from ros_isolated_test import __version__
from ros_isolated_test.runner.junit_model import Case, Outcome, Suite
from ros_isolated_test.runner.xml_text import name_token
from ros_isolated_test.runner.xml_text import xml_safe as _xml_safe
from ros_isolated_test.runner.xunit_reader import TEXT_LIMIT
from ros_isolated_test.schemas import junit_schema

_COUNTS = ("tests", "failures", "errors", "skipped")


def xml_safe(text: str, limit: int | None = TEXT_LIMIT) -> str:
    """:func:`~ros_isolated_test.runner.xml_text.xml_safe`, capped for a result file."""
    return _xml_safe(text, limit)


def timestamp(when: float | None = None) -> str:
    """Local time to the second, the form every reader (and our schema) accepts."""
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(when))


def hostname() -> str:
    """The machine's name; never empty (the schema requires one)."""
    return socket.gethostname().strip() or "localhost"


def _seconds(value: float) -> str:
    return f"{max(value, 0.0):.3f}"


def build(suite: Suite) -> etree._Element:
    """The ``<testsuites>`` tree of one suite, counts recomputed from its cases."""
    suite_name = name_token(suite.name, "ros_isolated_test.result")
    root = etree.Element("testsuites", name=suite_name)
    counts = {
        "tests": len(suite.cases),
        "failures": suite.count(Outcome.FAILURE),
        "errors": suite.count(Outcome.ERROR),
        "skipped": suite.count(Outcome.SKIPPED),
    }
    for key in ("tests", "failures", "errors"):
        root.set(key, str(counts[key]))
    root.set("time", _seconds(suite.time))
    element = etree.SubElement(root, "testsuite", name=suite_name)
    for key in _COUNTS:
        element.set(key, str(counts[key]))
    element.set("time", _seconds(suite.time))
    element.set("timestamp", suite.timestamp)
    element.set("hostname", name_token(suite.hostname, "localhost", 255))
    properties = etree.SubElement(element, "properties")
    for name, value in {**suite.properties, "runner_version": __version__}.items():
        etree.SubElement(
            properties, "property", name=name_token(name, "property"), value=xml_safe(value, 4096)
        )
    for case in suite.cases:
        _add_case(element, case)
    _add_output(element, suite.system_out, suite.system_err)
    return root


def _add_case(parent: etree._Element, case: Case) -> None:
    element = etree.SubElement(
        parent,
        "testcase",
        classname=name_token(case.classname, "unnamed"),
        name=name_token(case.name, "unnamed"),
        time=_seconds(case.time),
    )
    if case.outcome is not Outcome.PASSED:
        message = xml_safe(case.message)
        outcome = etree.SubElement(element, case.outcome.value, message=message)
        if case.type:
            outcome.set("type", xml_safe(case.type, 256))
        text = xml_safe(case.text) or message
        if text:
            outcome.text = text
    _add_output(element, case.system_out, case.system_err)


def _add_output(parent: etree._Element, out: str, err: str) -> None:
    for tag, text in (("system-out", out), ("system-err", err)):
        safe = xml_safe(text)
        if safe.strip():
            etree.SubElement(parent, tag).text = safe


def problems(root: etree._Element) -> list[str]:
    """Why a tree is not canonical: schema errors, then counts that disagree with cases."""
    schema = junit_schema()
    if not schema.validate(root):
        return [f"line {error.line}: {error.message}" for error in list(schema.error_log)]  # type: ignore[call-overload]
    found: list[str] = []
    for suite in root.iter("testsuite"):
        cases = suite.findall("testcase")
        expected = {
            "tests": len(cases),
            "failures": sum(1 for case in cases if case.find("failure") is not None),
            "errors": sum(1 for case in cases if case.find("error") is not None),
            "skipped": sum(1 for case in cases if case.find("skipped") is not None),
        }
        for key, value in expected.items():
            if suite.get(key) != str(value):
                found.append(
                    f"suite {suite.get('name')}: {key}={suite.get(key)}, cases say {value}"
                )
    return found


@dataclass(frozen=True)
class Rendered:
    """A canonical file's bytes, and whether it reports a failure or an error."""

    data: bytes
    failed: bool


def render(suite: Suite) -> Rendered:
    """The canonical file; an invalid document becomes a valid one saying why (a failure).

    ``failed`` is read from the document written, so a result replaced by the internal
    error case fails the run instead of passing it silently.
    """
    root = build(suite)
    found = problems(root)
    if found:
        root = build(_internal_error(suite, found))
        if problems(root):
            root = build(_internal_error(_bare(suite), found))
    failed = any(True for _ in root.iter("failure", "error"))
    data = bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True))
    return Rendered(data, failed)


def _bare(suite: Suite) -> Suite:
    """The suite stripped of everything it got from outside, for the last-resort file."""
    return Suite(
        name="ros_isolated_test.result",
        cases=suite.cases,
        time=0.0,
        timestamp=timestamp(),
        hostname="localhost",
    )


def _internal_error(suite: Suite, found: list[str]) -> Suite:
    failed = sum(1 for case in suite.cases if case.outcome.failed)
    message = (
        "ros-isolated-test built a result that does not match its own schema (a bug: please "
        f"report it). The test had {len(suite.cases)} case(s), {failed} failed or errored. "
        f"Schema problems: {'; '.join(found[:5])}"
    )
    case = Case.saying(
        name_token(suite.name, "ros_isolated_test.result"),
        "result file",
        Outcome.ERROR,
        message,
        "InternalError",
    )
    return Suite(
        name=suite.name,
        cases=[case],
        time=suite.time,
        timestamp=timestamp(),
        hostname=hostname(),
        properties={key: value for key, value in suite.properties.items() if key and value},
    )


def write_atomically(path: Path, data: bytes) -> None:
    """Replace ``path`` whole, so a reader (or a kill) never sees half a result file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, temp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(temp_name, 0o644)
        os.replace(temp_name, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp_name)
        raise


def holds_exactly(path: Path, data: bytes) -> bool:
    """Whether the file still holds ``data`` (the placeholder the test did not replace).

    Opened without blocking and read only if it is a regular file: a test may leave a
    FIFO at the path, and that must not hang the runner.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return False
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        return False
    with os.fdopen(fd, "rb") as handle:
        return handle.read(len(data) + 1) == data
