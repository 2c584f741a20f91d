"""Reading what a run's output capture left: the result file checked, the runner's lines apart.

Shared by the capture tests that run the CLI or the RUNNER: the result file must match
schemas/junit.xsd whatever bytes the test printed, and the console holds the test's
bytes with the runner's own lines (:data:`PREFIX`) among them.
"""

from __future__ import annotations

import re
from pathlib import Path

from lxml import etree

from ros_isolated_test.process.capture import PREFIX
from ros_isolated_test.xunit import validate

#: What a full disk (or /dev/full) makes the system say.
NO_SPACE = "No space left on device"


def result_root(path: Path) -> etree._Element:
    """The parsed result file, failing the test unless it matches schemas/junit.xsd."""
    assert path.is_file(), f"no result file at {path}"
    root = etree.parse(str(path), etree.XMLParser(resolve_entities=False)).getroot()
    assert validate.problems(root) == [], f"{path} does not match schemas/junit.xsd"
    return root


def runner_lines_removed(console: bytes) -> bytes:
    """The console without the runner's lines (and the newline put before each)."""
    return re.sub(rb"\n?" + re.escape(PREFIX.encode()) + rb"[^\n]*\n", b"", console)
