"""The result file: every xUnit XML the runner writes or reads is handled here.

Written with lxml's element API (never string templates), so escaping is right by
construction; text is cleaned of characters XML 1.0 cannot carry first, because one
ANSI colour code would otherwise make the whole file unreadable to every CI tool.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from lxml import etree

from ros_isolated_test import __version__

#: Longest text kept in one message or element, in characters.
MAX_TEXT_CHARS = 64 * 1024
_ANSI_ESCAPE = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b[@-Z\\-_]")
_ILLEGAL_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


class CaseKind(Enum):
    """The one outcome of a synthesized test case."""

    PASSED = "passed"
    FAILURE = "failure"
    ERROR = "error"
    SKIPPED = "skipped"


@dataclass(frozen=True)
class Case:
    """A test case the runner writes for a test that wrote none (or could not run)."""

    kind: CaseKind
    message: str = ""
    time: float = 0.0


def xml_safe(text: str, limit: int | None = MAX_TEXT_CHARS) -> str:
    """Text any XML 1.0 reader accepts: colour codes dropped, other illegal characters shown.

    Over ``limit`` the head and tail are kept around a marked cut.
    """
    text = _ANSI_ESCAPE.sub("", text)
    text = _ILLEGAL_XML.sub(lambda match: f"\\x{ord(match.group()):02x}", text)
    if limit is not None and len(text) > limit:
        half = limit // 2
        cut = len(text) - 2 * half
        text = f"{text[:half]}\n[... {cut} characters cut ...]\n{text[-half:]}"
    return text


def render(
    package: str,
    test_name: str,
    case: Case,
    properties: Mapping[str, str],
) -> bytes:
    """One suite ``<package>.<test>`` with one case, as ``<testsuites>`` bytes."""
    suite_name = f"{package}.{test_name}"
    root = etree.Element("testsuites")
    suite = etree.SubElement(
        root,
        "testsuite",
        name=suite_name,
        tests="1",
        failures=str(int(case.kind is CaseKind.FAILURE)),
        errors=str(int(case.kind is CaseKind.ERROR)),
        skipped=str(int(case.kind is CaseKind.SKIPPED)),
        time=f"{case.time:.3f}",
        timestamp=time.strftime("%Y-%m-%dT%H:%M:%S"),
        hostname=socket.gethostname() or "localhost",
    )
    props = etree.SubElement(suite, "properties")
    for name, value in {**properties, "runner_version": __version__}.items():
        etree.SubElement(props, "property", name=name, value=xml_safe(value, 4096))
    testcase = etree.SubElement(
        suite, "testcase", classname=suite_name, name=test_name, time=f"{case.time:.3f}"
    )
    if case.kind is not CaseKind.PASSED:
        message = xml_safe(case.message)
        child = etree.SubElement(testcase, case.kind.value, message=message)
        if message:
            child.text = message
    return bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True))


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
    """Whether the file still holds ``data`` (the placeholder the test did not replace)."""
    try:
        with open(path, "rb") as handle:
            return handle.read(len(data) + 1) == data
    except OSError:
        return False


@dataclass(frozen=True)
class Verdict:
    """What a result file written by the test itself says."""

    readable: bool
    failed: bool
    detail: str = ""


def _safe_parser(recover: bool = False) -> etree.XMLParser:
    # A test's result file is written by arbitrary code: no entities, DTDs or network.
    return etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, recover=recover)


def read_verdict(path: Path, package: str | None = None) -> Verdict:
    """Parse a test's own result file, tidying it in place if needed, as run_test.py does.

    A ``.gtest.xml`` gets ``<package>.`` put before each classname that lacks it, so
    results from different packages do not merge in CI reports.
    """
    try:
        data = path.read_bytes()
    except OSError as error:
        return Verdict(readable=False, failed=True, detail=f"cannot read {path}: {error}")
    try:
        root = etree.fromstring(data, _safe_parser())
        tidied = False
    except etree.XMLSyntaxError as error:
        text = xml_safe(data.decode("utf-8", errors="replace"), limit=None)
        text = re.sub(r"^<\?xml[^>]*\?>", "", text.lstrip("\ufeff"))
        try:
            root = etree.fromstring(text.encode(), _safe_parser())
        except etree.XMLSyntaxError:
            return Verdict(readable=False, failed=True, detail=f"invalid XML in {path}: {error}")
        tidied = True
    if root is None:
        return Verdict(readable=False, failed=True, detail=f"no XML in {path}")
    prefixed = False
    if package and path.name.endswith(".gtest.xml"):
        for case in root.iter("testcase"):
            classname = case.get("classname", "")
            if not classname.startswith(f"{package}."):
                case.set("classname", f"{package}.{classname}")
                prefixed = True
    if tidied or prefixed:
        write_atomically(path, bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8")))
    failed = _reports_failure(root)
    detail = f"{path} reports failures or errors" if failed else ""
    return Verdict(readable=True, failed=failed, detail=detail)


def _reports_failure(root: etree._Element) -> bool:
    """Failures by the counts or by the elements: producers get one or the other wrong."""
    for node in root.iter("testsuites", "testsuite"):
        for attribute in ("failures", "errors"):
            try:
                if int(float(node.get(attribute, "0") or "0")) > 0:
                    return True
            except ValueError:
                continue
    return any(True for _ in root.iter("failure", "error"))
